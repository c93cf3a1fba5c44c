//! Online row alignment: the vertical offset between the left and the right image, estimated
//! from the images themselves, tracked over frames and removed before matching.
//!
//! The Minoru's two cameras are not row-aligned, and a calibration stops fitting when the
//! camera is knocked; two rows of misalignment multiply a matcher's error several times. The
//! estimator needs no calibration (with one it measures the residual after rectification):
//!
//! 1. **Features**: on a grid of cells over the left image, the point with the most texture
//!    in both directions (the smaller of the summed |dI/dx| and |dI/dy| over its patch): a
//!    vertical offset shows only where intensity changes from row to row, and the match needs
//!    horizontal texture to be found at all.
//! 2. **Search**: each feature's 16x9 patch is compared (SAD, after the right image's mean is
//!    scaled to the left's) with the right image at every disparity of the search range and
//!    every vertical offset in `-max..=max`; per offset the best disparity counts. An offset
//!    whose cost is not clearly below every offset two or more rows away is no vote (an
//!    untextured or repetitive patch); a vote is refined to sub-pixel by a parabola.
//! 3. **Estimate**: the median of the votes, when enough votes agree with it.
//! 4. **Tracking** ([`RowAligner`]): estimates near the current one are smoothed in; one far
//!    from it is an outlier unless three in a row agree (the camera was knocked).
//!
//! The correction shifts the right image by the tracked offset (linear interpolation between
//! two rows; nothing is done below [`APPLY_MIN_PX`]), so every matcher benefits.

use hvs_runtime::config::StereoConfig;
use hvs_shared::messages::StereoAlgorithm;

use crate::{ImageView, MatchStats, StereoError, StereoMatcher};

/// Patch width, px (one 16-byte SAD per row).
pub const PATCH_W: usize = 16;
/// Patch height, px.
pub const PATCH_H: usize = 9;
/// Feature grid: columns x rows of cells.
pub const GRID: (usize, usize) = (8, 6);
/// Offsets smaller than this are not applied (the images are left untouched).
pub const APPLY_MIN_PX: f32 = 0.25;
/// A vote needs its offset's cost this far below every offset two rows or more away.
const UNIQUENESS: f32 = 0.85;
/// Fewest votes for an estimate.
const MIN_VOTES: usize = 6;
/// Share of the votes within 0.75 px of the median for an estimate.
const MIN_AGREEMENT: f32 = 0.4;

/// One frame's measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShiftEstimate {
    /// Vertical offset, px: the right image's content lies this many rows below the left's.
    pub shift_px: f32,
    /// Features that voted.
    pub votes: u32,
    /// Votes within 0.75 px of the estimate.
    pub agreeing: u32,
}

/// The right image's mean scaled to the left's, as a factor in 1/256 (the estimator's own
/// equalisation: it runs before the matcher's).
fn gain_q8(left: &[u8], right: &[u8]) -> u32 {
    let sl: u64 = left.iter().map(|&v| v as u64).sum();
    let sr: u64 = right.iter().map(|&v| v as u64).sum::<u64>().max(1);
    ((sl * 256) / sr).clamp(64, 1024) as u32
}

/// Sum of absolute differences of two 16-byte rows (the compiler makes it one `psadbw`).
#[inline]
fn sad16(a: &[u8], b: &[u8]) -> u32 {
    a[..PATCH_W]
        .iter()
        .zip(&b[..PATCH_W])
        .map(|(&x, &y)| x.abs_diff(y) as u32)
        .sum()
}

/// The texture score of the patch whose top-left corner is `(x, y)`: min(sum |gx|, sum |gy|).
fn texture(img: &ImageView<'_>, x: usize, y: usize) -> u32 {
    let (mut gx, mut gy) = (0u32, 0u32);
    for yy in y..y + PATCH_H {
        let row = img.row(yy);
        let below = img.row(yy + 1);
        for xx in x..x + PATCH_W {
            gx += row[xx + 1].abs_diff(row[xx]) as u32;
            gy += below[xx].abs_diff(row[xx]) as u32;
        }
    }
    gx.min(gy)
}

/// Estimates the vertical offset of `right` against `left` for disparities
/// `min_disp..=max_disp` and offsets up to `max_shift` rows either way. `None` when too few
/// features agree (an untextured view).
pub fn estimate_shift(
    left: ImageView<'_>,
    right: ImageView<'_>,
    min_disp: usize,
    max_disp: usize,
    max_shift: usize,
) -> Option<ShiftEstimate> {
    let (w, h) = (left.width, left.height);
    if right.width != w || right.height != h {
        return None;
    }
    // Patches whose every search position lies inside the right image.
    let x0 = max_disp;
    let x1 = w.checked_sub(PATCH_W + 2)?;
    let y0 = max_shift;
    let y1 = h.checked_sub(PATCH_H + max_shift + 2)?;
    if x1 <= x0 + GRID.0 || y1 <= y0 + GRID.1 {
        return None;
    }
    let gain = gain_q8(left.data, right.data);
    let mut right_eq = vec![0u8; w * (PATCH_H + 2 * max_shift + 1)];
    let n_shift = 2 * max_shift + 1;
    let mut votes = Vec::with_capacity(GRID.0 * GRID.1);
    let (cw, ch) = ((x1 - x0) / GRID.0, (y1 - y0) / GRID.1);
    let mut cost_by_shift = vec![u32::MAX; n_shift];
    for gy in 0..GRID.1 {
        for gx in 0..GRID.0 {
            // The most textured patch of the cell, sampled every 4 px.
            let (cx, cy) = (x0 + gx * cw, y0 + gy * ch);
            let mut best = (0u32, cx, cy);
            for y in (cy..cy + ch).step_by(4) {
                for x in (cx..cx + cw).step_by(4) {
                    let t = texture(&left, x, y);
                    if t > best.0 {
                        best = (t, x, y);
                    }
                }
            }
            let (t, fx, fy) = best;
            // At least 4 grey levels a pixel of texture in both directions.
            if t < (4 * PATCH_W * PATCH_H) as u32 {
                continue;
            }
            // The right rows this feature can reach, equalised once.
            let top = fy - max_shift;
            let rows = PATCH_H + 2 * max_shift;
            for r in 0..rows {
                let src = right.row(top + r);
                let dst = &mut right_eq[r * w..(r + 1) * w];
                for (d, &s) in dst.iter_mut().zip(src) {
                    *d = ((s as u32 * gain + 128) >> 8).min(255) as u8;
                }
            }
            cost_by_shift.fill(u32::MAX);
            let d_hi = max_disp.min(fx);
            for (si, cost) in cost_by_shift.iter_mut().enumerate() {
                for d in min_disp..=d_hi {
                    let rx = fx - d;
                    let mut c = 0u32;
                    for r in 0..PATCH_H {
                        let l = &left.row(fy + r)[fx..fx + PATCH_W];
                        let off = (si + r) * w + rx;
                        c += sad16(l, &right_eq[off..off + PATCH_W]);
                        if c >= *cost {
                            break;
                        }
                    }
                    *cost = (*cost).min(c);
                }
            }
            if let Some(v) = vote(&cost_by_shift) {
                votes.push(v - max_shift as f32);
            }
        }
    }
    if votes.len() < MIN_VOTES {
        return None;
    }
    votes.sort_by(f32::total_cmp);
    let median = votes[votes.len() / 2];
    let agreeing = votes
        .iter()
        .filter(|&&v| (v - median).abs() <= 0.75)
        .count();
    if (agreeing as f32) < MIN_AGREEMENT * votes.len() as f32 {
        return None;
    }
    // The mean of the agreeing votes: the median of sub-pixel votes is biased by their steps.
    let near: Vec<f32> = votes
        .iter()
        .copied()
        .filter(|&v| (v - median).abs() <= 0.75)
        .collect();
    let shift_px = near.iter().sum::<f32>() / near.len() as f32;
    Some(ShiftEstimate {
        shift_px,
        votes: votes.len() as u32,
        agreeing: agreeing as u32,
    })
}

/// The winning offset index of one feature, sub-pixel, if it is unique.
fn vote(cost: &[u32]) -> Option<f32> {
    let (best_i, &best) = cost.iter().enumerate().min_by_key(|(_, c)| **c)?;
    let rival = cost
        .iter()
        .enumerate()
        .filter(|(i, _)| i.abs_diff(best_i) >= 2)
        .map(|(_, &c)| c)
        .min()?;
    if best as f32 >= UNIQUENESS * rival as f32 {
        return None;
    }
    let sub = if best_i > 0 && best_i + 1 < cost.len() {
        let (a, b, c) = (
            cost[best_i - 1] as f32,
            best as f32,
            cost[best_i + 1] as f32,
        );
        let denom = a - 2.0 * b + c;
        if denom > 0.0 {
            (0.5 * (a - c) / denom).clamp(-0.5, 0.5)
        } else {
            0.0
        }
    } else {
        0.0
    };
    Some(best_i as f32 + sub)
}

/// Shifts `right` by `shift_px` rows into `out`: row `y` of `out` is row `y + shift_px` of
/// `right` (linear interpolation between two rows, edge rows repeated).
pub fn apply_shift(right: ImageView<'_>, shift_px: f32, out: &mut [u8]) {
    let (w, h) = (right.width, right.height);
    let whole = shift_px.floor();
    let frac = ((shift_px - whole) * 256.0).round() as u32;
    let whole = whole as isize;
    let row_at = |y: isize| right.row(y.clamp(0, h as isize - 1) as usize);
    for (y, dst) in out.chunks_exact_mut(w).take(h).enumerate() {
        let a = row_at(y as isize + whole);
        if frac == 0 {
            dst.copy_from_slice(a);
            continue;
        }
        let b = row_at(y as isize + whole + 1);
        for ((d, &p), &q) in dst.iter_mut().zip(a).zip(b) {
            *d = ((p as u32 * (256 - frac) + q as u32 * frac + 128) >> 8) as u8;
        }
    }
}

/// Tracks the offset over frames and corrects the right image.
#[derive(Debug, Clone)]
pub struct RowAligner {
    max_shift: usize,
    every_n: u32,
    frames: u32,
    current: Option<f32>,
    pending: Vec<f32>,
    scratch: Vec<u8>,
}

/// What the aligner holds after a frame, for the disparity header and the stage's status.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AlignStatus {
    /// The tracked offset, px (`None` until a first estimate).
    pub shift_px: Option<f32>,
    /// The offset applied to this frame, px (0 when below [`APPLY_MIN_PX`]).
    pub applied_px: f32,
    /// Whether this frame was measured.
    pub measured: bool,
}

impl RowAligner {
    /// An aligner that searches up to `max_shift` rows and measures every `every_n` frames.
    pub fn new(max_shift: usize, every_n: u32) -> Self {
        Self {
            max_shift,
            every_n: every_n.max(1),
            frames: 0,
            current: None,
            pending: Vec::new(),
            scratch: Vec::new(),
        }
    }

    /// Folds one measurement into the tracked offset.
    pub fn track(&mut self, e: ShiftEstimate) {
        match self.current {
            None => self.current = Some(e.shift_px),
            Some(c) if (e.shift_px - c).abs() <= 1.0 => {
                self.current = Some(c + 0.3 * (e.shift_px - c));
                self.pending.clear();
            }
            Some(_) => {
                // Far from the tracked offset: an outlier, unless it persists.
                self.pending.push(e.shift_px);
                if self.pending.len() > 3 {
                    self.pending.remove(0);
                }
                if self.pending.len() == 3 {
                    let lo = self.pending.iter().copied().fold(f32::MAX, f32::min);
                    let hi = self.pending.iter().copied().fold(f32::MIN, f32::max);
                    if hi - lo <= 0.5 {
                        self.current = Some(self.pending[1]);
                        self.pending.clear();
                    }
                }
            }
        }
    }

    /// Measures this frame if due, and returns the right image to match: `right` itself
    /// when no offset worth applying is tracked, else the corrected copy.
    pub fn align<'a>(
        &'a mut self,
        left: ImageView<'_>,
        right: ImageView<'a>,
        min_disp: usize,
        max_disp: usize,
    ) -> (ImageView<'a>, AlignStatus) {
        let measured = self.frames.is_multiple_of(self.every_n);
        self.frames = self.frames.wrapping_add(1);
        if measured && let Some(e) = estimate_shift(left, right, min_disp, max_disp, self.max_shift)
        {
            self.track(e);
        }
        let shift = self.current.unwrap_or(0.0);
        let mut status = AlignStatus {
            shift_px: self.current,
            applied_px: 0.0,
            measured,
        };
        if shift.abs() < APPLY_MIN_PX {
            return (right, status);
        }
        self.scratch.resize(right.data.len(), 0);
        apply_shift(right, shift, &mut self.scratch);
        status.applied_px = shift;
        (
            ImageView {
                data: &self.scratch,
                width: right.width,
                height: right.height,
            },
            status,
        )
    }
}

/// A matcher with the row alignment in front of it ([`crate::matcher_for`] builds one when
/// `row_align.enabled`).
pub struct AlignedMatcher {
    inner: Box<dyn StereoMatcher>,
    aligner: RowAligner,
    min_disp: usize,
    max_disp: usize,
}

impl AlignedMatcher {
    /// Wraps `inner` with the alignment `config.row_align` describes.
    pub fn new(inner: Box<dyn StereoMatcher>, config: &StereoConfig) -> Self {
        let r = &config.row_align;
        Self {
            inner,
            aligner: RowAligner::new(r.max_shift_px as usize, r.every_n_frames),
            min_disp: config.min_disp as usize,
            max_disp: config.max_disp as usize,
        }
    }
}

impl StereoMatcher for AlignedMatcher {
    fn algorithm(&self) -> StereoAlgorithm {
        self.inner.algorithm()
    }

    fn compute(
        &mut self,
        left: ImageView<'_>,
        right: ImageView<'_>,
        out_q8: &mut [u16],
    ) -> Result<MatchStats, StereoError> {
        crate::check_pair(&left, &right, out_q8.len())?;
        let (right, status) = self
            .aligner
            .align(left, right, self.min_disp, self.max_disp);
        let mut stats = self.inner.compute(left, right, out_q8)?;
        stats.row_align = Some(status);
        Ok(stats)
    }

    fn confidence(&self) -> Option<&[u8]> {
        self.inner.confidence()
    }
}

#[cfg(test)]
mod tests;
