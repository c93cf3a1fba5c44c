//! Synthetic stereo pairs with known disparity, for tests and benchmarks: textured planes
//! (fronto-parallel, slanted sideways like a hallway wall, tilted like a floor) and webcam
//! defects. Everything is deterministic for a given seed.

/// A synthetic pair with its exact disparity.
#[derive(Debug, Clone)]
pub struct SyntheticPair {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Left image.
    pub left: Vec<u8>,
    /// Right image.
    pub right: Vec<u8>,
    /// Disparity of every left pixel in px (NaN where the left pixel is not visible on the right).
    pub disparity_px: Vec<f32>,
}

fn hash(x: i64, y: i64, seed: u64) -> u64 {
    let mut v = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ seed.wrapping_mul(0x1656_67B1_9E37_79F9);
    v ^= v >> 31;
    v = v.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    v ^= v >> 29;
    v
}

/// Smooth random texture value at a real position (bilinear value noise over two octaves),
/// in grey levels, so that a surface can be resampled at subpixel positions.
pub fn texture_at(x: f32, y: f32, seed: u64) -> f32 {
    let octave = |scale: f32, s: u64| {
        let (fx, fy) = (x / scale, y / scale);
        let (x0, y0) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - x0, fy - y0);
        let v = |dx: i64, dy: i64| (hash(x0 as i64 + dx, y0 as i64 + dy, s) % 256) as f32;
        let top = v(0, 0) * (1.0 - tx) + v(1, 0) * tx;
        let bottom = v(0, 1) * (1.0 - tx) + v(1, 1) * tx;
        top * (1.0 - ty) + bottom * ty
    };
    0.6 * octave(1.5, seed) + 0.4 * octave(6.0, seed ^ 0x55)
}

/// A textured plane: disparity `d(x, y) = a*x + b*y + c` (a: sideways slant, b: floor-like
/// tilt). The right image shows the same surface texture at `x - d`.
pub fn plane(width: usize, height: usize, a: f32, b: f32, c: f32, seed: u64) -> SyntheticPair {
    let mut left = vec![0u8; width * height];
    let mut right = vec![0u8; width * height];
    let mut disparity_px = vec![f32::NAN; width * height];
    for y in 0..height {
        for x in 0..width {
            let i = y * width + x;
            // Texture is attached to the surface: parametrise it by left-image coordinates.
            left[i] = texture_at(x as f32, y as f32, seed).clamp(0.0, 255.0) as u8;
            let d = a * x as f32 + b * y as f32 + c;
            if x as f32 - d >= 0.0 {
                disparity_px[i] = d;
            }
            // Right pixel xr shows the left point x with x - d(x) = xr, i.e.
            // x = (xr + b*y + c) / (1 - a).
            let xl = (x as f32 + b * y as f32 + c) / (1.0 - a);
            right[i] = texture_at(xl, y as f32, seed).clamp(0.0, 255.0) as u8;
        }
    }
    SyntheticPair {
        width,
        height,
        left,
        right,
        disparity_px,
    }
}

/// Replaces a rectangle of the left image (and the matching part of the right image) with a
/// flat grey: a textureless wall that a matcher must leave invalid rather than guess.
pub fn flatten_region(pair: &mut SyntheticPair, x0: usize, x1: usize, grey: u8) {
    let w = pair.width;
    for y in 0..pair.height {
        for x in x0..x1.min(w) {
            pair.left[y * w + x] = grey;
            let d = pair.disparity_px[y * w + x];
            if d.is_finite() {
                let xr = (x as f32 - d).round();
                if xr >= 0.0 {
                    pair.right[y * w + xr as usize] = grey;
                }
            }
        }
    }
}

/// Webcam defects applied to a right image: `gain * p + offset`, Gaussian noise of `sigma`
/// grey levels, then a downward shift by `vertical_shift_px` rows (edge rows repeated).
pub fn degrade(
    right: &mut [u8],
    width: usize,
    gain: f32,
    offset: f32,
    sigma: f32,
    vertical_shift_px: usize,
    seed: u64,
) {
    let height = right.len() / width.max(1);
    let mut state = seed | 1;
    let mut uniform = move || {
        // xorshift64*: deterministic and fast; quality is ample for image noise.
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        ((state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    for p in right.iter_mut() {
        // Box-Muller.
        let n = (-2.0 * uniform().ln()).sqrt() * (2.0 * std::f64::consts::PI * uniform()).cos();
        let v = *p as f64 * gain as f64 + offset as f64 + n * sigma as f64;
        *p = v.round().clamp(0.0, 255.0) as u8;
    }
    if vertical_shift_px > 0 && height > vertical_shift_px {
        for y in (0..height).rev() {
            let src = y.saturating_sub(vertical_shift_px);
            if src != y {
                right.copy_within(src * width..(src + 1) * width, y * width);
            }
        }
    }
}

/// Share of pixels with known disparity whose estimate is within `tolerance_px` (invalid
/// estimates count as wrong), and the share of known pixels given any estimate.
pub fn score(
    pair: &SyntheticPair,
    estimate_q8: &[u16],
    tolerance_px: f32,
    x_from: usize,
) -> (f32, f32) {
    let mut known = 0usize;
    let mut good = 0usize;
    let mut dense = 0usize;
    for y in 0..pair.height {
        for x in x_from..pair.width {
            let i = y * pair.width + x;
            let truth = pair.disparity_px[i];
            if !truth.is_finite() {
                continue;
            }
            known += 1;
            if let Some(d) = crate::q8_to_px(estimate_q8[i]) {
                dense += 1;
                if (d - truth).abs() <= tolerance_px {
                    good += 1;
                }
            }
        }
    }
    let k = known.max(1) as f32;
    (good as f32 / k, dense as f32 / k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fronto_parallel_right_image_is_a_shift() {
        let p = plane(64, 8, 0.0, 0.0, 5.0, 3);
        for y in 0..8 {
            for x in 5..64 {
                assert_eq!(p.left[y * 64 + x], p.right[y * 64 + x - 5]);
            }
        }
        assert!(p.disparity_px[3].is_nan() && p.disparity_px[5] == 5.0);
    }

    #[test]
    fn degrade_applies_gain_offset_and_shift() {
        let mut r: Vec<u8> = (0..40).map(|i| i as u8 * 4).collect();
        degrade(&mut r, 10, 0.5, 10.0, 0.0, 1, 1);
        assert_eq!(&r[10..20], &[10, 12, 14, 16, 18, 20, 22, 24, 26, 28]);
        assert_eq!(&r[0..10], &r[10..20], "edge row repeated");
    }
}
