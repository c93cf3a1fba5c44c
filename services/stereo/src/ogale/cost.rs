//! Matching costs of a hypothesis row by row (Birchfield-Tomasi or census, with the vertical
//! search), the disparity a hypothesis gives a pixel, and the subpixel fit.

use super::params::MatchFunction;
use super::prepare::{Hypothesis, Prepared};
use crate::post::parabola_offset;

/// Half-width of the window of the subpixel fit (5x3: 2 columns and 1 row either side).
const SUBPIXEL_RX: usize = 2;
/// Half-height of the window of the subpixel fit.
const SUBPIXEL_RY: usize = 1;

impl Prepared {
    /// Dissimilarity of left row `y` under `hyp` into `out[xa..xb]`: `4 * BT` (in quarter grey
    /// levels) or the census Hamming distance, the smallest over the searched right rows.
    #[inline]
    pub(super) fn cost_row(&self, y: usize, hyp: &Hypothesis, out: &mut [u16], tmp: &mut Vec<u16>) {
        self.cost_row_at(y, y, hyp, out);
        let v = self.vertical_search;
        if v > 0 {
            tmp.resize(out.len(), 0);
            for yr in y.saturating_sub(v)..(y + v + 1).min(self.h) {
                if yr != y {
                    self.cost_row_at(y, yr, hyp, tmp);
                    for (o, &t) in out[hyp.xa..hyp.xb].iter_mut().zip(&tmp[hyp.xa..hyp.xb]) {
                        *o = (*o).min(t);
                    }
                }
            }
        }
    }

    /// Dissimilarity of left row `y` against right row `yr` under `hyp`.
    #[inline]
    fn cost_row_at(&self, y: usize, yr: usize, hyp: &Hypothesis, out: &mut [u16]) {
        let w = self.w;
        let img = &self.right[hyp.image];
        let (xa, xb) = (hyp.xa, hyp.xb);
        let (ra, rb) = (
            (xa as isize - hyp.s) as usize,
            (xb as isize - hyp.s) as usize,
        );
        let (lrow, rrow) = (y * w..(y + 1) * w, yr * img.w..(yr + 1) * img.w);
        let out = &mut out[xa..xb];
        if self.match_fn == MatchFunction::Census {
            let cl = &self.lcensus[lrow][xa..xb];
            let cr = &img.census[rrow][ra..rb];
            for ((o, &a), &b) in out.iter_mut().zip(cl).zip(cr) {
                *o = (a ^ b).count_ones() as u16;
            }
            return;
        }
        let l = &self.l2[lrow.clone()][xa..xb];
        let llo = &self.llo2[lrow.clone()][xa..xb];
        let lhi = &self.lhi2[lrow][xa..xb];
        let r = &img.v2[rrow.clone()][ra..rb];
        let rlo = &img.lo2[rrow.clone()][ra..rb];
        let rhi = &img.hi2[rrow][ra..rb];
        let it = out
            .iter_mut()
            .zip(l)
            .zip(llo)
            .zip(lhi)
            .zip(r)
            .zip(rlo)
            .zip(rhi);
        for ((((((o, &lv), &llv), &lhv), &rv), &rlv), &rhv) in it {
            // Values are doubled grey levels (<= 510), so i16 cannot overflow.
            let (lv, llv, lhv) = (lv as i16, llv as i16, lhv as i16);
            let (rv, rlv, rhv) = (rv as i16, rlv as i16, rhv as i16);
            let d1 = (rlv - lv).max(lv - rhv).max(0);
            let d2 = (llv - rv).max(rv - lhv).max(0);
            // (d1 + d2) in doubled grey levels = 4 * BT.
            *o = (d1 + d2) as u16;
        }
    }

    /// Disparity (1/256 px) of `hyp` at column `x`, and the right column it points at.
    #[inline(always)]
    pub(super) fn disparity_at(&self, hyp: &Hypothesis, x: usize) -> (i32, usize) {
        let pos = self.right[hyp.image].pos_q8[(x as isize - hyp.s) as usize];
        let d_q8 = 256 * x as i32 - pos;
        (d_q8, (x as i32 - ((d_q8 + 128) >> 8)) as usize)
    }

    /// Subpixel offset, in original right px, of the minimum of a parabola through the 5x3 SAD
    /// at the hypothesis' resampled right column moved by -1, 0, +1 (0 near the borders).
    pub(super) fn subpixel_offset(&self, left: &[u8], hyp: &Hypothesis, x: usize, y: usize) -> f32 {
        let img = &self.right[hyp.image];
        let xr = x as isize - hyp.s;
        let (rx, ry) = (SUBPIXEL_RX as isize, SUBPIXEL_RY);
        if y < ry
            || y + ry >= self.h
            || x < SUBPIXEL_RX
            || x + SUBPIXEL_RX >= self.w
            || xr - rx - 1 < 0
            || xr + rx + 1 >= img.w as isize
        {
            return 0.0;
        }
        let xr = xr as usize;
        let mut c = [0u32; 3];
        for yy in y - ry..=y + ry {
            let l = &left[yy * self.w + x - SUBPIXEL_RX..=yy * self.w + x + SUBPIXEL_RX];
            let row = &img.grey[yy * img.w..(yy + 1) * img.w];
            for (k, ck) in c.iter_mut().enumerate() {
                let r = &row[xr + k - 1 - SUBPIXEL_RX..=xr + k - 1 + SUBPIXEL_RX];
                *ck += l
                    .iter()
                    .zip(r)
                    .map(|(&a, &b)| (a as i32 - b as i32).unsigned_abs())
                    .sum::<u32>();
            }
        }
        img.m * parabola_offset(c[0] as f32, c[1] as f32, c[2] as f32)
    }
}
