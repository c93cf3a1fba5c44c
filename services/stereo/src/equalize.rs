//! The reference system's equalisation step: scale the right image so that its mean intensity
//! equals the left's (`IR *= sum(IL) / sum(IR)`). It corrects a global gain difference between
//! the two webcams, nothing else (no offset, gamma or vignetting).

/// Writes `right * sum(left) / sum(right)` (rounded, saturated to 255) into `out` and returns
/// the ratio applied. A black right image is copied unchanged (ratio 1).
pub fn equalize_right(left: &[u8], right: &[u8], out: &mut [u8]) -> f32 {
    let sum_l: u64 = left.iter().map(|&p| p as u64).sum();
    let sum_r: u64 = right.iter().map(|&p| p as u64).sum();
    if sum_r == 0 {
        out.copy_from_slice(right);
        return 1.0;
    }
    let ratio = sum_l as f64 / sum_r as f64;
    // A 256-entry table: one multiply per grey level instead of per pixel.
    let mut lut = [0u8; 256];
    for (v, slot) in lut.iter_mut().enumerate() {
        *slot = (v as f64 * ratio).round().min(255.0) as u8;
    }
    for (o, &p) in out.iter_mut().zip(right) {
        *o = lut[p as usize];
    }
    ratio as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equalisation_undoes_a_global_gain() {
        let left: Vec<u8> = (0..1000).map(|i| (40 + (i * 7) % 150) as u8).collect();
        let right: Vec<u8> = left
            .iter()
            .map(|&p| (p as f32 * 0.8).round() as u8)
            .collect();
        let mut out = vec![0; left.len()];
        let ratio = equalize_right(&left, &right, &mut out);
        assert!((ratio - 1.25).abs() < 0.01, "ratio {ratio}");
        let worst = left
            .iter()
            .zip(&out)
            .map(|(&a, &b)| (a as i32 - b as i32).abs())
            .max()
            .unwrap_or(0);
        assert!(worst <= 1, "worst difference {worst}");
    }

    #[test]
    fn black_right_image_is_left_alone() {
        let mut out = vec![9; 4];
        assert_eq!(equalize_right(&[10, 20, 30, 40], &[0; 4], &mut out), 1.0);
        assert_eq!(out, vec![0; 4]);
    }
}
