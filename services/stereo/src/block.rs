//! Correlation block matching with the sum of absolute differences (SAD), winner-take-all,
//! with a texture threshold, a uniqueness ratio and a parabolic subpixel fit.
//!
//! Cost per disparity is computed with running sums: for every disparity a column sum of
//! absolute differences slides down the image and a row sum slides along it, so a window costs
//! O(1) per pixel and disparity whatever its size.

use hvs_shared::messages::StereoAlgorithm;

use crate::equalize::equalize_right;
use crate::{ImageView, MatchStats, StereoError, StereoMatcher, check_pair};

/// Block-matching parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockParams {
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px (inclusive).
    pub max_disp: u32,
    /// Window size (odd).
    pub window: u32,
    /// Apply the reference equalisation to the right image first.
    pub equalize: bool,
    /// A match is rejected unless its cost is this many percent below every match more than
    /// one pixel away (0 disables).
    pub uniqueness_pct: u32,
    /// Minimum mean |horizontal gradient| of the left window, grey levels per pixel; flatter
    /// windows are marked invalid rather than matched by chance (0 disables).
    pub texture_threshold: u32,
    /// Refine disparities to subpixel with a parabola through the three costs around the best.
    pub subpixel: bool,
}

impl Default for BlockParams {
    fn default() -> Self {
        Self {
            min_disp: 9,
            max_disp: 55,
            window: 9,
            equalize: true,
            uniqueness_pct: 10,
            texture_threshold: 4,
            subpixel: true,
        }
    }
}

impl BlockParams {
    /// Checks the parameters on their own (image size is checked per call).
    pub fn validate(&self) -> Result<(), StereoError> {
        if self.max_disp <= self.min_disp {
            return Err(StereoError::BadRange {
                min: self.min_disp,
                max: self.max_disp,
            });
        }
        if self.window.is_multiple_of(2) || !(3..=31).contains(&self.window) {
            return Err(StereoError::BadParameter(format!(
                "window {} must be odd and in 3..=31",
                self.window
            )));
        }
        Ok(())
    }
}

/// SAD block matcher with reusable scratch buffers.
#[derive(Debug)]
pub struct BlockMatcher {
    params: BlockParams,
    right_eq: Vec<u8>,
    best_cost: Vec<u32>,
    second_cost: Vec<u32>,
    best_disp: Vec<u16>,
    cost_below: Vec<u32>,
    cost_above: Vec<u32>,
    prev_cost: Vec<u32>,
    cur_cost: Vec<u32>,
    col_sum: Vec<u32>,
    texture: Vec<u32>,
}

impl BlockMatcher {
    /// Creates a matcher; fails on an empty disparity range or a bad window.
    pub fn new(params: BlockParams) -> Result<Self, StereoError> {
        params.validate()?;
        Ok(Self {
            params,
            right_eq: Vec::new(),
            best_cost: Vec::new(),
            second_cost: Vec::new(),
            best_disp: Vec::new(),
            cost_below: Vec::new(),
            cost_above: Vec::new(),
            prev_cost: Vec::new(),
            cur_cost: Vec::new(),
            col_sum: Vec::new(),
            texture: Vec::new(),
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &BlockParams {
        &self.params
    }

    fn resize(&mut self, n: usize, width: usize) {
        for v in [
            &mut self.best_cost,
            &mut self.second_cost,
            &mut self.cost_below,
            &mut self.cost_above,
            &mut self.prev_cost,
            &mut self.cur_cost,
            &mut self.texture,
        ] {
            v.clear();
            v.resize(n, u32::MAX);
        }
        self.best_disp.clear();
        self.best_disp.resize(n, 0);
        self.right_eq.resize(n, 0);
        self.col_sum.clear();
        self.col_sum.resize(width, 0);
    }

    /// Window sums of |L(x+1) - L(x-1)| for the texture test.
    fn texture_sums(&mut self, left: &ImageView<'_>) {
        let (w, h) = (left.width, left.height);
        let r = (self.params.window / 2) as usize;
        let grad = |x: usize, y: usize| -> u32 {
            let row = left.row(y);
            let a = row[x.saturating_sub(1)] as i32;
            let b = row[(x + 1).min(w - 1)] as i32;
            (a - b).unsigned_abs()
        };
        self.col_sum.iter_mut().for_each(|c| *c = 0);
        for y in 0..2 * r {
            for x in 0..w {
                self.col_sum[x] += grad(x, y);
            }
        }
        for y in r..h - r {
            for x in 0..w {
                self.col_sum[x] += grad(x, y + r);
            }
            let mut s: u32 = self.col_sum[..2 * r + 1].iter().sum();
            for x in r..w - r {
                if x > r {
                    s = s + self.col_sum[x + r] - self.col_sum[x - r - 1];
                }
                self.texture[y * w + x] = s;
            }
            for x in 0..w {
                self.col_sum[x] -= grad(x, y - r);
            }
        }
    }
}

impl StereoMatcher for BlockMatcher {
    fn algorithm(&self) -> StereoAlgorithm {
        StereoAlgorithm::BmSad
    }

    fn compute(
        &mut self,
        left: ImageView<'_>,
        right: ImageView<'_>,
        out_q8: &mut [u16],
    ) -> Result<MatchStats, StereoError> {
        check_pair(&left, &right, out_q8.len())?;
        let (w, h) = (left.width, left.height);
        let p = self.params.clone();
        let r = (p.window / 2) as usize;
        let (dmin, dmax) = (p.min_disp as usize, p.max_disp as usize);
        if w < dmin + 2 * r + 2 || h < 2 * r + 1 || w <= dmax {
            return Err(StereoError::ImageTooSmall {
                width: w,
                height: h,
                max_disp: p.max_disp,
                window: p.window,
            });
        }
        let n = w * h;
        self.resize(n, w);
        if p.equalize {
            equalize_right(left.data, right.data, &mut self.right_eq);
        } else {
            self.right_eq.copy_from_slice(right.data);
        }
        if p.texture_threshold > 0 {
            self.texture_sums(&left);
        }
        let right_px = std::mem::take(&mut self.right_eq);

        for d in dmin..=dmax {
            // Columns x with a full window in both images: x - d - r >= 0 and x + r < w.
            let x0 = d + r;
            if x0 + r >= w {
                break;
            }
            let ad = |y: usize, x: usize| -> u32 {
                (left.data[y * w + x] as i32 - right_px[y * w + x - d] as i32).unsigned_abs()
            };
            self.col_sum.iter_mut().for_each(|c| *c = 0);
            for y in 0..2 * r {
                for x in x0 - r..w {
                    self.col_sum[x] += ad(y, x);
                }
            }
            for y in r..h - r {
                let yb = y + r;
                let lrow = &left.data[yb * w..(yb + 1) * w];
                let rrow = &right_px[yb * w..(yb + 1) * w];
                for x in x0 - r..w {
                    self.col_sum[x] += (lrow[x] as i32 - rrow[x - d] as i32).unsigned_abs();
                }
                let mut s: u32 = self.col_sum[x0 - r..=x0 + r].iter().sum();
                let base = y * w;
                for x in x0..w - r {
                    if x > x0 {
                        s = s + self.col_sum[x + r] - self.col_sum[x - r - 1];
                    }
                    let i = base + x;
                    self.cur_cost[i] = s;
                    let best = self.best_cost[i];
                    let bd = self.best_disp[i] as usize;
                    if s < best {
                        // The old best stays a competitor if it is not adjacent to the new one.
                        if best != u32::MAX && d > bd + 1 {
                            self.second_cost[i] = self.second_cost[i].min(best);
                        }
                        self.best_cost[i] = s;
                        self.best_disp[i] = d as u16;
                        self.cost_below[i] = if d > dmin {
                            self.prev_cost[i]
                        } else {
                            u32::MAX
                        };
                        self.cost_above[i] = u32::MAX;
                    } else {
                        if best != u32::MAX && bd + 1 == d {
                            self.cost_above[i] = s;
                        }
                        if d > bd + 1 && s < self.second_cost[i] {
                            self.second_cost[i] = s;
                        }
                    }
                }
                let yt = y - r;
                let lrow = &left.data[yt * w..(yt + 1) * w];
                let rrow = &right_px[yt * w..(yt + 1) * w];
                for x in x0 - r..w {
                    self.col_sum[x] -= (lrow[x] as i32 - rrow[x - d] as i32).unsigned_abs();
                }
            }
            std::mem::swap(&mut self.prev_cost, &mut self.cur_cost);
        }
        self.right_eq = right_px;

        let area = (p.window * p.window) as u64;
        let mut valid = 0u32;
        for (i, out) in out_q8.iter_mut().enumerate() {
            let best = self.best_cost[i];
            *out = 0;
            if best == u32::MAX {
                continue;
            }
            if p.texture_threshold > 0
                && (self.texture[i] as u64) < p.texture_threshold as u64 * area
            {
                continue;
            }
            let second = self.second_cost[i];
            if p.uniqueness_pct > 0
                && second != u32::MAX
                && (best as u64) * (100 + p.uniqueness_pct as u64) >= (second as u64) * 100
            {
                continue;
            }
            let d = self.best_disp[i] as f32;
            let mut offset = 0.0f32;
            let (below, above) = (self.cost_below[i], self.cost_above[i]);
            if p.subpixel && below != u32::MAX && above != u32::MAX {
                let (c0, c1, c2) = (below as f32, best as f32, above as f32);
                let denom = c0 - 2.0 * c1 + c2;
                if denom > 0.0 {
                    offset = ((c0 - c2) / (2.0 * denom)).clamp(-0.5, 0.5);
                }
            }
            let q8 = ((d + offset) * 256.0).round();
            if q8 >= 1.0 {
                *out = q8.min(u16::MAX as f32) as u16;
                valid += 1;
            }
        }
        Ok(MatchStats { valid_px: valid })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic texture: hashed value noise, smooth enough to match at 1 px shifts.
    pub(crate) fn texture(w: usize, h: usize, seed: u32) -> Vec<u8> {
        let hash = |x: i64, y: i64| -> u32 {
            let mut v =
                (x as u32).wrapping_mul(0x9E37_79B1) ^ (y as u32).wrapping_mul(0x85EB_CA77) ^ seed;
            v ^= v >> 15;
            v = v.wrapping_mul(0x2C1B_3C6D);
            v ^= v >> 12;
            v
        };
        let mut img = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let v = (hash(x as i64, y as i64) % 160) as i32
                    + (hash(x as i64 / 4, y as i64 / 4) % 60) as i32;
                img[y * w + x] = (20 + v).clamp(0, 255) as u8;
            }
        }
        img
    }

    /// Right image of a fronto-parallel plane at integer disparity `d`.
    fn shift(left: &[u8], w: usize, h: usize, d: usize, seed: u32) -> Vec<u8> {
        let filler = texture(w, h, seed);
        let mut right = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                right[y * w + x] = if x + d < w {
                    left[y * w + x + d]
                } else {
                    filler[y * w + x]
                };
            }
        }
        right
    }

    fn matcher(min: u32, max: u32) -> BlockMatcher {
        BlockMatcher::new(BlockParams {
            min_disp: min,
            max_disp: max,
            ..BlockParams::default()
        })
        .expect("valid params")
    }

    #[test]
    fn fronto_parallel_plane_is_recovered() {
        let (w, h) = (160, 90);
        let left = texture(w, h, 1);
        let right = shift(&left, w, h, 17, 2);
        let mut out = vec![0u16; w * h];
        let stats = matcher(9, 40)
            .compute(
                ImageView::new(&left, w, h).unwrap(),
                ImageView::new(&right, w, h).unwrap(),
                &mut out,
            )
            .expect("compute");
        let all_valid = out.iter().filter(|&&q| q != 0).count();
        assert_eq!(all_valid as u32, stats.valid_px);
        // Score where the true match is inside the right image (x - 17 - r >= 0).
        let valid: Vec<f32> = (0..h)
            .flat_map(|y| (22..w).map(move |x| (x, y)))
            .filter_map(|(x, y)| crate::q8_to_px(out[y * w + x]))
            .collect();
        assert!(valid.len() > w * h / 2, "only {} valid", valid.len());
        let good = valid.iter().filter(|&&d| (d - 17.0).abs() <= 0.5).count();
        assert!(
            good * 100 >= valid.len() * 97,
            "{good} of {} within 0.5 px",
            valid.len()
        );
    }

    #[test]
    fn textureless_region_comes_out_invalid() {
        let (w, h) = (120, 60);
        let mut left = texture(w, h, 3);
        for y in 0..h {
            for x in 60..w {
                left[y * w + x] = 128;
            }
        }
        let right = shift(&left, w, h, 12, 4);
        let mut out = vec![0u16; w * h];
        matcher(5, 30)
            .compute(
                ImageView::new(&left, w, h).unwrap(),
                ImageView::new(&right, w, h).unwrap(),
                &mut out,
            )
            .expect("compute");
        // Well inside the flat block (away from its textured border) nothing may be claimed.
        for y in 10..h - 10 {
            for x in 75..w - 10 {
                assert_eq!(out[y * w + x], 0, "flat pixel ({x},{y}) got a disparity");
            }
        }
    }

    #[test]
    fn gain_difference_is_absorbed_by_equalisation() {
        let (w, h) = (160, 90);
        let left = texture(w, h, 5);
        let right: Vec<u8> = shift(&left, w, h, 20, 6)
            .iter()
            .map(|&p| (p as f32 * 0.7) as u8)
            .collect();
        let mut out = vec![0u16; w * h];
        matcher(9, 40)
            .compute(
                ImageView::new(&left, w, h).unwrap(),
                ImageView::new(&right, w, h).unwrap(),
                &mut out,
            )
            .expect("compute");
        let valid: Vec<f32> = out.iter().filter_map(|&q| crate::q8_to_px(q)).collect();
        let good = valid.iter().filter(|&&d| (d - 20.0).abs() <= 1.0).count();
        assert!(valid.len() > w * h / 2);
        assert!(good * 100 >= valid.len() * 95, "{good} of {}", valid.len());
    }

    #[test]
    fn bad_inputs_give_clear_errors() {
        assert_eq!(
            BlockMatcher::new(BlockParams {
                min_disp: 30,
                max_disp: 30,
                ..BlockParams::default()
            })
            .unwrap_err(),
            StereoError::BadRange { min: 30, max: 30 }
        );
        let img = vec![0u8; 40 * 30];
        let other = vec![0u8; 41 * 30];
        let mut out = vec![0u16; 40 * 30];
        let err = matcher(9, 55)
            .compute(
                ImageView::new(&img, 40, 30).unwrap(),
                ImageView::new(&other, 41, 30).unwrap(),
                &mut out,
            )
            .unwrap_err();
        assert!(err.to_string().contains("40x30"), "{err}");
        let err = matcher(9, 55)
            .compute(
                ImageView::new(&img, 40, 30).unwrap(),
                ImageView::new(&img, 40, 30).unwrap(),
                &mut out,
            )
            .unwrap_err();
        assert!(matches!(err, StereoError::ImageTooSmall { .. }), "{err}");
        assert!(ImageView::new(&img, 41, 30).is_err());
    }
}
