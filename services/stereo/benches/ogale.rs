//! Criterion benchmark of the Ogale & Aloimonos matcher at the robot's two resolutions:
//! 320x240 with disparities 9..55 and 640x480 with 18..110, on a synthetic textured scene
//! (a slanted wall behind a nearer box, mild webcam noise). Both variants, fronto-parallel
//! only (the config default) and with five stretch factors.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use hvs_stereo::ogale::{OgaleMatcher, OgaleParams, OgaleVariant};
use hvs_stereo::synthetic::{degrade, plane};
use hvs_stereo::{ImageView, StereoMatcher};

/// The stretch set benchmarked besides the fronto-parallel default.
const STRETCH: [f32; 5] = [0.8, 0.9, 1.0, 1.1, 1.25];

/// A slanted wall (d from `max` to about `min` across the image) with noise and a 1-px
/// vertical shift on the right image.
fn scene(w: usize, h: usize, min: u32, max: u32) -> (Vec<u8>, Vec<u8>) {
    let slope = -((max - min) as f32) / w as f32 * 0.8;
    let mut pair = plane(w, h, slope, 0.0, max as f32 - 2.0, 3);
    degrade(&mut pair.right, w, 0.9, 5.0, 2.0, 1, 5);
    (pair.left, pair.right)
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("ogale");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(5));
    group.warm_up_time(Duration::from_secs(1));
    for (w, h, min, max) in [(320usize, 240usize, 9u32, 55u32), (640, 480, 18, 110)] {
        let (left, right) = scene(w, h, min, max);
        let mut out = vec![0u16; w * h];
        for variant in [OgaleVariant::Components, OgaleVariant::Diffusion] {
            for (label, stretch) in [("fronto", vec![1.0]), ("stretch5", STRETCH.to_vec())] {
                // The stretched runs at 640x480 take seconds each; keep the suite short.
                if w == 640 && label == "stretch5" && variant == OgaleVariant::Diffusion {
                    continue;
                }
                let params = OgaleParams {
                    min_disp: min,
                    max_disp: max,
                    stretch,
                    ..OgaleParams::default().with_variant(variant)
                };
                let Ok(mut matcher) = OgaleMatcher::new(params) else {
                    panic!("benchmark parameters must be valid");
                };
                let name = format!("{variant:?}/{label}/{w}x{h}").to_lowercase();
                group.bench_function(name, |b| {
                    b.iter(|| {
                        let l = ImageView {
                            data: &left,
                            width: w,
                            height: h,
                        };
                        let r = ImageView {
                            data: &right,
                            width: w,
                            height: h,
                        };
                        black_box(matcher.compute(black_box(l), black_box(r), &mut out))
                    })
                });
            }
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
