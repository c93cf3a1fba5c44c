//! Benchmark of one stereo pair plus ground truth (`render_pair`) at 640x480 and 320x240, in
//! the straight-hallway map and the maze, from their start poses.

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use hvs_sim::{GridMap, Renderer, StereoRig, WebcamDefects, sim_rng};

fn load(name: &str) -> GridMap {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../config/maps")
        .join(name);
    match GridMap::load(&path) {
        Ok(m) => m,
        Err(e) => panic!("{e}"),
    }
}

fn bench_render(c: &mut Criterion) {
    for map_name in ["straight.txt", "maze.txt"] {
        let map = load(map_name);
        let pose = map.start_pose();
        for (label, rig) in [
            ("640x480", StereoRig::vga()),
            ("320x240", StereoRig::qvga()),
        ] {
            let renderer = Renderer::new(&map, rig);
            let n = rig.pixels();
            let (mut l, mut r, mut g) = (vec![0u8; n], vec![0u8; n], vec![0u16; n]);
            c.bench_function(&format!("render_pair+gt {label} {map_name}"), |b| {
                b.iter(|| {
                    renderer
                        .render_pair(
                            black_box(&pose),
                            black_box(&pose),
                            &mut l,
                            &mut r,
                            Some(&mut g),
                        )
                        .map_err(|e| e.to_string())
                })
            });
        }
    }
    let map = load("straight.txt");
    let rig = StereoRig::vga();
    let renderer = Renderer::new(&map, rig);
    let n = rig.pixels();
    let (mut l, mut r) = (vec![0u8; n], vec![0u8; n]);
    let pose = map.start_pose();
    let _ = renderer.render_pair(&pose, &pose, &mut l, &mut r, None);
    let defects = WebcamDefects::typical();
    let mut rng = sim_rng(1);
    c.bench_function("defects typical 640x480 pair", |b| {
        b.iter(|| {
            let (mut a, mut bb) = (l.clone(), r.clone());
            defects
                .apply(&mut a, &mut bb, 640, 480, &mut rng)
                .map_err(|e| e.to_string())
        })
    });
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
