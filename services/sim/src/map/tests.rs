//! Tests of the map parser, ray casting and the footprint test.

use super::*;

const BOX: &str = "@cell_m 1\n#####\n#...#\n#.>.#\n#...#\n#####\n";

fn parse_err(text: &str) -> MapError {
    match GridMap::parse(text, "t.txt") {
        Ok(m) => panic!("expected an error, parsed {m:?}"),
        Err(e) => e,
    }
}

#[test]
fn parses_box_and_frame() {
    let m = GridMap::parse(BOX, "box").unwrap();
    assert_eq!(m.width_cells(), 5);
    assert_eq!(m.height_cells(), 5);
    assert_eq!(m.cell_m(), 1.0);
    let s = m.start_pose();
    assert_eq!((s.x_m, s.y_m, s.heading_rad), (2.5, 2.5, 0.0));
    assert!(m.is_wall_at(0.5, 0.5));
    assert!(!m.is_wall_at(1.5, 1.5));
    assert!(m.is_wall_at(-0.1, 2.5));
    assert!(m.is_wall_at(2.5, 5.1));
}

#[test]
fn top_line_is_north_and_rows_may_be_short() {
    // Floor only in the top-left corner region; the short row is padded with wall.
    let m = GridMap::parse("@cell_m 0.5\n#.^\n#\n###", "t").unwrap();
    assert_eq!(m.width_cells(), 3);
    assert_eq!(m.height_cells(), 3);
    // Text row 0 is the north row: y in [1.0, 1.5).
    assert!(!m.is_wall_at(0.75, 1.25));
    assert!(m.is_wall_at(0.75, 0.75)); // padded cell
    let s = m.start_pose();
    assert!((s.x_m - 1.25).abs() < 1e-12 && (s.y_m - 1.25).abs() < 1e-12);
    assert!((s.heading_deg() - 90.0).abs() < 1e-9);
}

#[test]
fn markers_give_headings() {
    for (ch, deg) in [('>', 0.0), ('^', 90.0), ('<', 180.0), ('v', 270.0)] {
        let m = GridMap::parse(&format!("###\n#{ch}#\n###"), "t").unwrap();
        assert!((m.start_pose().heading_deg() - deg).abs() < 1e-9, "{ch}");
    }
}

#[test]
fn errors_name_line_and_column() {
    match parse_err("; c\n@name x\n###\n#.x>#\n###") {
        MapError::UnknownChar { line, col, ch, .. } => assert_eq!((line, col, ch), (4, 3, 'x')),
        e => panic!("{e}"),
    }
    let e = parse_err("###\n#>.\n#.<\n###");
    match &e {
        MapError::MultipleStarts {
            line,
            col,
            first_line,
            first_col,
            ..
        } => assert_eq!((*line, *col, *first_line, *first_col), (3, 3, 2, 2)),
        e => panic!("{e}"),
    }
    assert!(e.to_string().starts_with("t.txt:3:3:"), "{e}");
    assert!(matches!(parse_err("###\n#..\n"), MapError::NoStart { .. }));
    assert!(matches!(parse_err("; only\n\n"), MapError::Empty { .. }));
    assert!(matches!(parse_err(""), MapError::Empty { .. }));
    match parse_err("@cell_m  abc\n#>#") {
        MapError::BadDirective {
            line, col, value, ..
        } => {
            assert_eq!((line, col, value.as_str()), (1, 10, "abc"))
        }
        e => panic!("{e}"),
    }
    assert!(matches!(
        parse_err("@cell_m -1\n#>#"),
        MapError::BadDirective { .. }
    ));
    assert!(matches!(
        parse_err("@foo 1\n#>#"),
        MapError::UnknownDirective { line: 1, .. }
    ));
    assert!(matches!(
        parse_err("#>#\n@cell_m 1"),
        MapError::DirectiveAfterGrid { line: 2, .. }
    ));
    match parse_err("@cell_m 1\n@start 0.5 0.5 0\n###\n#..\n###") {
        MapError::StartOnWall { line, .. } => assert_eq!(line, 2),
        e => panic!("{e}"),
    }
    assert!(matches!(
        parse_err("@start 1.2 0.7 0\n###\n#>.\n###"),
        MapError::MultipleStarts { .. }
    ));
}

#[test]
fn start_directive_gives_exact_pose() {
    let m = GridMap::parse("@cell_m 1\n@start 1.2 1.7 45\n####\n#..#\n#..#\n####", "t").unwrap();
    let s = m.start_pose();
    assert_eq!((s.x_m, s.y_m), (1.2, 1.7));
    assert!((s.heading_deg() - 45.0).abs() < 1e-9);
}

#[test]
fn load_names_missing_file() {
    let e = GridMap::load("/nonexistent/dir/map.txt").unwrap_err();
    assert!(e.to_string().contains("/nonexistent/dir/map.txt"), "{e}");
}

#[test]
fn ray_distances_are_exact() {
    let m = GridMap::parse(BOX, "box").unwrap();
    let o = Vec2::new(2.5, 2.5);
    // Floor spans x in [1, 4]: east wall face at x = 4.
    let h = m.cast_ray(o, Vec2::new(1.0, 0.0)).unwrap();
    assert_eq!(h.distance_m, 1.5);
    assert_eq!(h.face, Face::West);
    assert_eq!((h.cell_col, h.cell_row), (4, 2));
    assert_eq!(h.u_m, 0.5);
    let h = m.cast_ray(o, Vec2::new(0.0, -3.0)).unwrap();
    assert_eq!(h.distance_m, 1.5);
    assert_eq!(h.face, Face::North);
    assert_eq!(h.normal, Vec2::new(0.0, 1.0));
    // A diagonal from (1.2, 1.3) towards the north-east hits the north wall (y = 4) at x = 3.9.
    let o2 = Vec2::new(1.2, 1.3);
    let h = m.cast_ray(o2, Vec2::new(1.0, 1.0)).unwrap();
    let expect = 2.7 * 2f64.sqrt();
    assert!((h.distance_m - expect).abs() < 1e-12, "{}", h.distance_m);
    assert!((h.point.x - 3.9).abs() < 1e-12 && h.point.y == 4.0);
    assert_eq!(h.face, Face::South);
    assert!((h.u_m - 0.9).abs() < 1e-12);
    // Shallow ray: from (1.1, 1.5) at slope 0.1 hits x = 4 at y = 1.79.
    let h = m
        .cast_ray(Vec2::new(1.1, 1.5), Vec2::new(1.0, 0.1))
        .unwrap();
    assert!((h.point.y - 1.79).abs() < 1e-12);
    assert!((h.distance_m - 2.9 * (1.01f64).sqrt()).abs() < 1e-12);
    // Origin in a wall or degenerate direction.
    assert!(
        m.cast_ray(Vec2::new(0.5, 0.5), Vec2::new(1.0, 0.0))
            .is_none()
    );
    assert!(m.cast_ray(o, Vec2::new(0.0, 0.0)).is_none());
}

#[test]
fn ray_into_open_edge_stops_at_grid_border() {
    // Floor reaches the east edge of the grid: the outside is wall.
    let m = GridMap::parse("@cell_m 0.5\n####\n#>..\n####", "t").unwrap();
    let h = m
        .cast_ray(Vec2::new(0.75, 0.75), Vec2::new(1.0, 0.0))
        .unwrap();
    assert_eq!(h.distance_m, 1.25);
    assert_eq!(h.cell_col, 4);
}

#[test]
fn rectangle_overlap() {
    let m = GridMap::parse(BOX, "box").unwrap();
    assert!(!m.rect_hits_wall(&Pose::from_deg(2.5, 2.5, 30.0), 0.438, 0.311));
    // Front edge at 3.95 < 4: free; at 4.05: hits.
    assert!(!m.rect_hits_wall(&Pose::from_deg(3.95 - 0.219, 2.5, 0.0), 0.438, 0.311));
    assert!(m.rect_hits_wall(&Pose::from_deg(4.05 - 0.219, 2.5, 0.0), 0.438, 0.311));
    // Rotated 45 degrees near a corner: the diagonal half-extent is (0.438+0.311)/2/sqrt(2).
    let r = (0.438 + 0.311) / 2.0 / 2f64.sqrt();
    assert!(!m.rect_hits_wall(&Pose::from_deg(4.0 - r - 0.01, 2.5, 45.0), 0.438, 0.311));
    assert!(m.rect_hits_wall(&Pose::from_deg(4.0 - r + 0.01, 2.5, 45.0), 0.438, 0.311));
}

#[test]
fn pose_from_str() {
    let p: Pose = "1.5, 2,90".parse().unwrap();
    assert_eq!((p.x_m, p.y_m), (1.5, 2.0));
    assert!((p.heading_deg() - 90.0).abs() < 1e-12);
    assert!("1,2".parse::<Pose>().is_err());
    let e = "1,x,3".parse::<Pose>().unwrap_err();
    assert!(e.to_string().contains("y_m"), "{e}");
}

#[test]
fn wall_contrast_directive() {
    let m = GridMap::parse(BOX, "box").unwrap();
    assert_eq!(m.wall_contrast(), 1.0, "default: the full texture");
    let m = GridMap::parse(&format!("@wall_contrast 0.25\n{BOX}"), "t").unwrap();
    assert_eq!(m.wall_contrast(), 0.25);
    let mut plain = GridMap::parse(&format!("@wall_contrast 0\n{BOX}"), "t").unwrap();
    assert_eq!(plain.wall_contrast(), 0.0);
    // The contrast does not change the map's texture seed.
    assert_eq!(plain.seed(), m.seed());
    plain.set_wall_contrast(2.0);
    assert_eq!(plain.wall_contrast(), 1.0);
    plain.set_wall_contrast(f64::NAN);
    assert_eq!(plain.wall_contrast(), 1.0);
    plain.set_wall_contrast(-1.0);
    assert_eq!(plain.wall_contrast(), 0.0);
    for bad in ["1.5", "-0.1", "x", "", "NaN"] {
        let text = format!("; c\n@wall_contrast {bad}\n{BOX}");
        match parse_err(&text) {
            MapError::BadDirective {
                line, directive, ..
            } => assert_eq!((line, directive.as_str()), (2, "wall_contrast"), "{bad}"),
            e => panic!("{bad}: {e}"),
        }
        let msg = parse_err(&text).to_string();
        assert!(msg.starts_with("t.txt:2:"), "{msg}");
    }
}
