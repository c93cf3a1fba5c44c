//! Checks every map in `config/maps`: it parses, the start pose is collision-free, it renders,
//! and the junction maps' geometry matches their names.

use std::path::PathBuf;

use hvs_sim::{GridMap, Pose, Renderer, RobotParams, StereoRig, Vec2};

fn maps_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../config/maps")
}

fn load(name: &str) -> GridMap {
    let path = maps_dir().join(name);
    GridMap::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Distance to the first wall from `p` along `dir`.
fn range(map: &GridMap, p: Vec2, dir: Vec2) -> f64 {
    map.cast_ray(p, dir).map_or(0.0, |h| h.distance_m)
}

/// Open (> 2 m) / blocked (< 1 m) pattern (left, front, right) at the junction ahead of the
/// start, found by walking forward from the start and looking sideways; `None` when no side
/// opening appears within 6 m. Also returns the junction centre's distance from the start.
fn junction_ahead(map: &GridMap) -> Option<((bool, bool, bool), f64)> {
    let s = map.start_pose();
    let (f, l) = (s.forward(), s.left());
    let r = l * -1.0;
    let mut span: Option<(f64, f64)> = None;
    let mut d = 0.0;
    while d < 6.0 {
        let p = s.position() + f * d;
        if map.is_wall_at(p.x, p.y) {
            break;
        }
        if range(map, p, l) > 2.0 || range(map, p, r) > 2.0 {
            span = Some(span.map_or((d, d), |(a, _)| (a, d)));
        } else if span.is_some() {
            break;
        }
        d += 0.01;
    }
    let (a, b) = span?;
    let centre = 0.5 * (a + b);
    let p = s.position() + f * centre;
    let classify = |dist: f64| {
        assert!(
            !(1.0..=2.0).contains(&dist),
            "{}: ambiguous range {dist} at the junction",
            map.name()
        );
        dist > 2.0
    };
    Some((
        (
            classify(range(map, p, l)),
            classify(range(map, p, f)),
            classify(range(map, p, r)),
        ),
        centre,
    ))
}

#[test]
fn every_map_parses_and_starts_collision_free() {
    let mut names: Vec<String> = std::fs::read_dir(maps_dir())
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".txt"))
        .collect();
    names.sort();
    for expected in [
        "straight.txt",
        "left_turn.txt",
        "right_turn.txt",
        "t_bottom.txt",
        "t_wall_left.txt",
        "t_wall_right.txt",
        "x.txt",
        "dead_end.txt",
        "maze.txt",
    ] {
        assert!(names.iter().any(|n| n == expected), "missing {expected}");
    }
    let robot = RobotParams::default();
    let rig = StereoRig::qvga();
    for name in &names {
        let map = load(name);
        assert!(!map.name().is_empty(), "{name} has an @name");
        let start = map.start_pose();
        assert!(
            !map.rect_hits_wall(&start, robot.length_m, robot.width_m),
            "{name}: start footprint overlaps a wall"
        );
        // It can turn on the spot at the start (hallways are wide enough).
        for deg in (0..360).step_by(15) {
            let p = Pose::new(start.x_m, start.y_m, f64::from(deg).to_radians());
            assert!(
                !map.rect_hits_wall(&p, robot.length_m, robot.width_m),
                "{name}: cannot turn to {deg} deg at the start"
            );
        }
        let n = rig.pixels();
        let (mut l, mut r, mut g) = (vec![0u8; n], vec![0u8; n], vec![0u16; n]);
        Renderer::new(&map, rig)
            .render_pair(&start, &start, &mut l, &mut r, Some(&mut g))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(g.iter().all(|&d| d > 0), "{name}: every pixel has a depth");
    }
}

#[test]
fn hallway_width_is_about_one_metre() {
    for name in ["straight.txt", "left_turn.txt", "x.txt", "dead_end.txt"] {
        let map = load(name);
        let s = map.start_pose();
        let p = s.position();
        let width = range(&map, p, s.left()) + range(&map, p, s.left() * -1.0);
        assert!(
            (1.0..=1.2).contains(&width),
            "{name}: hallway {width} m wide"
        );
    }
}

#[test]
fn junction_maps_match_their_names() {
    // (file, left open, front open, right open)
    let cases = [
        ("left_turn.txt", true, false, false),
        ("right_turn.txt", false, false, true),
        ("t_bottom.txt", true, false, true),
        ("t_wall_left.txt", false, true, true),
        ("t_wall_right.txt", true, true, false),
        ("x.txt", true, true, true),
    ];
    for (name, l, f, r) in cases {
        let map = load(name);
        let (pattern, centre_m) =
            junction_ahead(&map).unwrap_or_else(|| panic!("{name}: no junction ahead"));
        assert_eq!(pattern, (l, f, r), "{name}: (left, front, right) open");
        assert!(
            (1.5..=3.5).contains(&centre_m),
            "{name}: junction centre {centre_m} m ahead of the start"
        );
    }
    // No side openings in the straight hallway and the dead end.
    for name in ["straight.txt", "dead_end.txt"] {
        let map = load(name);
        assert!(junction_ahead(&map).is_none(), "{name} has a side opening");
    }
    let straight = load("straight.txt");
    let s = straight.start_pose();
    assert!(range(&straight, s.position(), s.forward()) > 5.0);
    let dead = load("dead_end.txt");
    let s = dead.start_pose();
    let ahead = range(&dead, s.position(), s.forward());
    assert!(
        (2.0..=3.5).contains(&ahead),
        "dead end wall {ahead} m ahead"
    );
}

#[test]
fn maze_is_connected_and_loop_rich() {
    let map = load("maze.txt");
    let (w, h) = (map.width_cells() as i64, map.height_cells() as i64);
    let size_w = map.width_m();
    let size_h = map.height_m();
    assert!((10.0..=13.0).contains(&size_w) && (10.0..=13.0).contains(&size_h));
    // Every floor cell is reachable from the start.
    let (sc, sr) = map.cell_of(map.start_pose().x_m, map.start_pose().y_m);
    let mut seen = vec![false; (w * h) as usize];
    let mut stack = vec![(sc, sr)];
    seen[(sr * w + sc) as usize] = true;
    while let Some((c, r)) = stack.pop() {
        for (dc, dr) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
            let (nc, nr) = (c + dc, r + dr);
            if !map.is_wall_cell(nc, nr) && !seen[(nr * w + nc) as usize] {
                seen[(nr * w + nc) as usize] = true;
                stack.push((nc, nr));
            }
        }
    }
    for r in 0..h {
        for c in 0..w {
            assert!(
                map.is_wall_cell(c, r) || seen[(r * w + c) as usize],
                "floor cell ({c},{r}) unreachable"
            );
        }
    }
    // Independent cycles = wall "islands": wall components (8-connected) not touching the
    // grid border.
    let mut comp = vec![false; (w * h) as usize];
    let mut islands = 0;
    for r0 in 0..h {
        for c0 in 0..w {
            if !map.is_wall_cell(c0, r0) || comp[(r0 * w + c0) as usize] {
                continue;
            }
            let mut touches_border = false;
            let mut stack = vec![(c0, r0)];
            comp[(r0 * w + c0) as usize] = true;
            while let Some((c, r)) = stack.pop() {
                if c == 0 || r == 0 || c == w - 1 || r == h - 1 {
                    touches_border = true;
                }
                for dc in -1..=1 {
                    for dr in -1..=1 {
                        let (nc, nr) = (c + dc, r + dr);
                        if nc < 0 || nr < 0 || nc >= w || nr >= h {
                            continue;
                        }
                        if map.is_wall_cell(nc, nr) && !comp[(nr * w + nc) as usize] {
                            comp[(nr * w + nc) as usize] = true;
                            stack.push((nc, nr));
                        }
                    }
                }
            }
            if !touches_border {
                islands += 1;
            }
        }
    }
    assert!(islands >= 4, "maze has {islands} independent loops");
}
