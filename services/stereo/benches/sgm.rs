//! Criterion benchmark of the census + SGM matcher at the robot's two working sizes
//! (320x240 with d = 9..55, 640x480 with d = 18..110), with the AVX2 kernels and with the
//! portable ones, on a rendered slanted textured plane (disparities 12..53 and 40..106) with
//! webcam defects on the right image (gain 0.8, offset 10, noise sigma 4). Paths = 5 with the
//! uniqueness test, the left-right check, the subpixel fit and the speckle filter on (the
//! default stereo config). Run with `cargo bench -p hvs-stereo --bench sgm`.

use criterion::{Criterion, criterion_group, criterion_main};
use hvs_runtime::config::StereoConfig;
use hvs_shared::messages::StereoAlgorithm;
use hvs_stereo::sgm::{SgmMatcher, simd_available};
use hvs_stereo::synthetic::{degrade, plane};
use hvs_stereo::{ImageView, StereoMatcher};

/// One benchmark case: size, disparity range and the plane `d = -16 x / w + b y / h + c`.
struct Case {
    width: usize,
    height: usize,
    min_disp: u32,
    max_disp: u32,
    b: f32,
    c: f32,
}

const CASES: [Case; 2] = [
    Case {
        width: 320,
        height: 240,
        min_disp: 9,
        max_disp: 55,
        b: 25.0,
        c: 28.0,
    },
    Case {
        width: 640,
        height: 480,
        min_disp: 18,
        max_disp: 110,
        b: 50.0,
        c: 56.0,
    },
];

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("sgm");
    group.sample_size(30);
    for case in &CASES {
        let (w, h) = (case.width, case.height);
        let mut pair = plane(w, h, -16.0 / w as f32, case.b / h as f32, case.c, 7);
        degrade(&mut pair.right, w, 0.8, 10.0, 4.0, 0, 8);
        let config = StereoConfig {
            algorithm: StereoAlgorithm::Sgm,
            min_disp: case.min_disp,
            max_disp: case.max_disp,
            ..StereoConfig::default()
        };
        let mut out = vec![0u16; w * h];
        for simd in [true, false] {
            if simd && !simd_available() {
                continue;
            }
            let Ok(matcher) = SgmMatcher::from_config(&config) else {
                panic!("bad benchmark config");
            };
            let mut matcher = matcher.with_simd(simd);
            let name = format!(
                "{w}x{h}_d{}-{}/{}",
                case.min_disp,
                case.max_disp,
                if simd { "avx2" } else { "portable" }
            );
            let left = ImageView {
                data: &pair.left,
                width: w,
                height: h,
            };
            let right = ImageView {
                data: &pair.right,
                width: w,
                height: h,
            };
            group.bench_function(name, |b| b.iter(|| matcher.compute(left, right, &mut out)));
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
