//! Criterion benchmark of the block matcher: each cost (SAD, SSD, NCC, census 5x5) with the
//! config defaults (window 9, equalisation, texture threshold, uniqueness, LR check, subpixel,
//! speckle filter) at the robot's two resolutions: 320x240 with disparities 9..=55 and
//! 640x480 with 18..=110, on one thread; plus the 640x480 case on two threads.
//!
//! Run: `cargo bench -p hvs-stereo --bench block`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use hvs_runtime::config::StereoConfig;
use hvs_shared::messages::StereoAlgorithm;
use hvs_stereo::block::{BlockMatcher, BlockParams};
use hvs_stereo::synthetic::{SyntheticPair, degrade, plane};
use hvs_stereo::{ImageView, StereoMatcher};

const ALGORITHMS: [(StereoAlgorithm, &str); 4] = [
    (StereoAlgorithm::BmSad, "sad"),
    (StereoAlgorithm::BmSsd, "ssd"),
    (StereoAlgorithm::BmNcc, "ncc"),
    (StereoAlgorithm::BmCensus, "census"),
];

/// A sideways-slanted, slightly tilted textured plane spanning most of the range, with
/// webcam-like noise on the right image.
fn scene(width: usize, height: usize, min_disp: u32, max_disp: u32) -> SyntheticPair {
    let (lo, hi) = (min_disp as f32 + 4.0, max_disp as f32 - 4.0);
    let a = -(hi - lo) / width as f32;
    let mut pair = plane(width, height, a, 0.0, hi, 42);
    degrade(&mut pair.right, width, 0.9, 5.0, 2.0, 0, 7);
    pair
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("block");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));
    for (width, height, min_disp, max_disp, threads) in [
        (320usize, 240usize, 9u32, 55u32, 1usize),
        (640, 480, 18, 110, 1),
        (640, 480, 18, 110, 2),
    ] {
        let pair = scene(width, height, min_disp, max_disp);
        for (algorithm, name) in ALGORITHMS {
            let config = StereoConfig {
                algorithm,
                min_disp,
                max_disp,
                ..StereoConfig::default()
            };
            let Ok(mut params) = BlockParams::from_config(&config) else {
                panic!("default config must be valid for {name}");
            };
            params.threads = threads;
            let Ok(mut matcher) = BlockMatcher::new(params) else {
                panic!("matcher for {name}");
            };
            let (Ok(left), Ok(right)) = (
                ImageView::new(&pair.left, width, height),
                ImageView::new(&pair.right, width, height),
            ) else {
                panic!("image views");
            };
            let mut out = vec![0u16; width * height];
            let id = BenchmarkId::new(name, format!("{width}x{height}-{threads}t"));
            group.bench_function(id, |b| {
                b.iter(|| {
                    let stats = matcher.compute(left, right, &mut out);
                    black_box(stats.is_ok())
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
