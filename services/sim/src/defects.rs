//! Webcam defects of the Minoru pair: gain/offset mismatch and vertical misalignment of the
//! right camera, sensor noise on both, and the right camera's capture delay.

use rand::{Rng, SeedableRng};

/// The deterministic random generator used by the simulator (PCG-XSL-RR 128/64, seedable).
pub type SimRng = rand_pcg::Pcg64Mcg;

/// A [`SimRng`] from a 64-bit seed.
pub fn sim_rng(seed: u64) -> SimRng {
    SimRng::seed_from_u64(seed)
}

/// Switchable webcam defects. [`WebcamDefects::none`] is an ideal pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WebcamDefects {
    /// Multiplicative gain of the right image (1 = none).
    pub gain: f32,
    /// Additive offset of the right image, grey levels (0 = none).
    pub offset: f32,
    /// Standard deviation of Gaussian noise added to both images, grey levels (0 = none).
    pub noise_sigma: f32,
    /// The right image is shifted down by this many pixels (negative: up); the rows uncovered at
    /// the edge repeat the nearest original row.
    pub vertical_shift_px: i32,
    /// The right camera captures this long after the left one, seconds; the caller renders the
    /// right eye from the robot pose at `time + right_delay_s`.
    pub right_delay_s: f64,
}

impl Default for WebcamDefects {
    fn default() -> Self {
        Self::none()
    }
}

/// Errors of [`WebcamDefects::apply`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DefectsError {
    /// An image buffer does not hold `width * height` pixels.
    #[error("{which} image has {got} pixels, expected {width}x{height}")]
    BufferSize {
        /// "left" or "right".
        which: &'static str,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Actual length.
        got: usize,
    },
}

impl WebcamDefects {
    /// No defects at all.
    pub const fn none() -> Self {
        WebcamDefects {
            gain: 1.0,
            offset: 0.0,
            noise_sigma: 0.0,
            vertical_shift_px: 0,
            right_delay_s: 0.0,
        }
    }

    /// A typical cheap webcam pair: 8 % brighter right camera with +6 levels offset, noise
    /// sigma 3 levels, right image 2 px lower, right camera 15 ms late (half a frame at 30 fps).
    pub const fn typical() -> Self {
        WebcamDefects {
            gain: 1.08,
            offset: 6.0,
            noise_sigma: 3.0,
            vertical_shift_px: 2,
            right_delay_s: 0.015,
        }
    }

    /// Whether any image defect (not counting the delay) is active.
    pub fn changes_images(&self) -> bool {
        self.gain != 1.0
            || self.offset != 0.0
            || self.noise_sigma > 0.0
            || self.vertical_shift_px != 0
    }

    /// Applies the image defects in place: the right image is shifted, then scaled by `gain` and
    /// offset; then Gaussian noise is added to both images; results are rounded and clamped to
    /// 0..=255. The delay is not applied here (it selects the right eye's pose).
    pub fn apply<R: Rng + ?Sized>(
        &self,
        left: &mut [u8],
        right: &mut [u8],
        width: usize,
        height: usize,
        rng: &mut R,
    ) -> Result<(), DefectsError> {
        for (which, img) in [("left", &*left), ("right", &*right)] {
            if Some(img.len()) != width.checked_mul(height) {
                return Err(DefectsError::BufferSize {
                    which,
                    width,
                    height,
                    got: img.len(),
                });
            }
        }
        if width == 0 || height == 0 {
            return Ok(());
        }
        if self.vertical_shift_px != 0 {
            shift_rows(right, width, height, self.vertical_shift_px);
        }
        if self.gain != 1.0 || self.offset != 0.0 {
            for p in right.iter_mut() {
                *p = to_u8(f32::from(*p) * self.gain + self.offset);
            }
        }
        if self.noise_sigma > 0.0 {
            let table = gaussian_table();
            for img in [left, right] {
                for chunk in img.chunks_mut(5) {
                    // Five 12-bit quantile indices from one 64-bit draw.
                    let mut bits = rng.next_u64();
                    for p in chunk {
                        let n = table[(bits & 0xfff) as usize];
                        bits >>= 12;
                        *p = to_u8(f32::from(*p) + n * self.noise_sigma);
                    }
                }
            }
        }
        Ok(())
    }
}

/// Standard normal samples by table: the 4096 quantiles `Phi^-1((i + 0.5) / 4096)`, indexed
/// by 12 random bits. Hand-written instead of `rand_distr::StandardNormal` for speed: the
/// ziggurat costs about 10 ns a sample (6 ms of noise per 640x480 pair), the table about a
/// fifth of that. Tails are cut at 3.5 sigma and the distribution is quantised to 1/4096 of
/// probability, which is invisible after rounding to 8-bit grey levels. The table is built
/// once from `rand_distr`-independent closed-form quantiles (Acklam's approximation, relative
/// error below 1.2e-9).
fn gaussian_table() -> &'static [f32; 4096] {
    static TABLE: std::sync::OnceLock<[f32; 4096]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0.0f32; 4096];
        for (i, v) in t.iter_mut().enumerate() {
            *v = normal_quantile((i as f64 + 0.5) / 4096.0) as f32;
        }
        t
    })
}

/// Inverse of the standard normal CDF for `p` in (0, 1) (P. J. Acklam's rational
/// approximation).
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    const P_LOW: f64 = 0.02425;
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < P_LOW {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - P_LOW {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

fn to_u8(v: f32) -> u8 {
    (v + 0.5).clamp(0.0, 255.0) as u8
}

/// Shifts rows down by `shift` (up if negative), replicating the edge row.
fn shift_rows(img: &mut [u8], width: usize, height: usize, shift: i32) {
    let h = height as i64;
    let s = i64::from(shift).clamp(-h, h);
    if s > 0 {
        for y in (0..height).rev() {
            let src = (y as i64 - s).max(0) as usize;
            img.copy_within(src * width..(src + 1) * width, y * width);
        }
    } else if s < 0 {
        for y in 0..height {
            let src = (y as i64 - s).min(h - 1) as usize;
            img.copy_within(src * width..(src + 1) * width, y * width);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp_image(w: usize, h: usize) -> Vec<u8> {
        (0..w * h).map(|i| ((i / w) * 10 + (i % w)) as u8).collect()
    }

    #[test]
    fn none_changes_nothing() {
        let (w, h) = (8, 6);
        let (mut l, mut r) = (ramp_image(w, h), ramp_image(w, h));
        let (l0, r0) = (l.clone(), r.clone());
        WebcamDefects::none()
            .apply(&mut l, &mut r, w, h, &mut sim_rng(1))
            .unwrap();
        assert_eq!((l, r), (l0, r0));
    }

    #[test]
    fn shift_down_replicates_top_row() {
        let (w, h) = (8, 6);
        let (mut l, mut r) = (ramp_image(w, h), ramp_image(w, h));
        let r0 = r.clone();
        let d = WebcamDefects {
            vertical_shift_px: 2,
            ..WebcamDefects::none()
        };
        d.apply(&mut l, &mut r, w, h, &mut sim_rng(1)).unwrap();
        assert_eq!(l, r0, "left untouched");
        for y in 0..h {
            let src = y.saturating_sub(2);
            assert_eq!(r[y * w..(y + 1) * w], r0[src * w..(src + 1) * w], "row {y}");
        }
        let mut r2 = r0.clone();
        let up = WebcamDefects {
            vertical_shift_px: -1,
            ..WebcamDefects::none()
        };
        up.apply(&mut l, &mut r2, w, h, &mut sim_rng(1)).unwrap();
        assert_eq!(r2[0..w], r0[w..2 * w]);
        assert_eq!(r2[(h - 1) * w..], r0[(h - 1) * w..]);
    }

    #[test]
    fn gain_and_offset_apply_to_right_only() {
        let (w, h) = (8, 6);
        let (mut l, mut r) = (ramp_image(w, h), ramp_image(w, h));
        let r0 = r.clone();
        let d = WebcamDefects {
            gain: 1.5,
            offset: -4.0,
            ..WebcamDefects::none()
        };
        d.apply(&mut l, &mut r, w, h, &mut sim_rng(1)).unwrap();
        assert_eq!(l, r0);
        for (a, b) in r.iter().zip(&r0) {
            let expect = (f32::from(*b) * 1.5 - 4.0).round().clamp(0.0, 255.0) as u8;
            assert_eq!(*a, expect);
        }
    }

    #[test]
    fn noise_has_requested_sigma_and_is_seeded() {
        let (w, h) = (200, 100);
        let mk = || (vec![128u8; w * h], vec![128u8; w * h]);
        let d = WebcamDefects {
            noise_sigma: 4.0,
            ..WebcamDefects::none()
        };
        let (mut l, mut r) = mk();
        d.apply(&mut l, &mut r, w, h, &mut sim_rng(7)).unwrap();
        for img in [&l, &r] {
            let n = img.len() as f64;
            let mean = img.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
            let var = img
                .iter()
                .map(|&v| (f64::from(v) - mean).powi(2))
                .sum::<f64>()
                / n;
            assert!((mean - 128.0).abs() < 0.1, "mean {mean}");
            // Rounding adds 1/12 to the variance.
            assert!((var.sqrt() - 4.0).abs() < 0.15, "sigma {}", var.sqrt());
        }
        assert_ne!(l, r, "left and right noise are independent");
        let (mut l2, mut r2) = mk();
        d.apply(&mut l2, &mut r2, w, h, &mut sim_rng(7)).unwrap();
        assert_eq!((l.clone(), r.clone()), (l2, r2), "same seed, same noise");
        let (mut l3, mut r3) = mk();
        d.apply(&mut l3, &mut r3, w, h, &mut sim_rng(8)).unwrap();
        assert_ne!(l, l3);
    }

    #[test]
    fn normal_quantiles_match_known_values() {
        assert!(normal_quantile(0.5).abs() < 1e-9);
        assert!((normal_quantile(0.975) - 1.959_963_985).abs() < 1e-7);
        assert!((normal_quantile(0.001) + 3.090_232_306).abs() < 1e-7);
        let t = gaussian_table();
        let mean = t.iter().map(|&v| f64::from(v)).sum::<f64>() / 4096.0;
        let var = t.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>() / 4096.0;
        assert!(
            mean.abs() < 1e-6 && (var - 1.0).abs() < 0.01,
            "{mean} {var}"
        );
    }

    #[test]
    fn wrong_size_is_an_error() {
        let d = WebcamDefects::typical();
        let (mut l, mut r) = (vec![0u8; 10], vec![0u8; 12]);
        let e = d.apply(&mut l, &mut r, 4, 3, &mut sim_rng(1)).unwrap_err();
        assert!(e.to_string().contains("left"), "{e}");
    }
}
