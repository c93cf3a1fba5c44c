//! hvs fusion: edges of the left image, the fused map (disparity kept at edge pixels only),
//! distances from disparities, and ranges over vertical windows, with no IPC.

pub mod canny;

use hvs_shared::config::RangeStatistic;
use hvs_shared::messages::{DISPARITY_SCALE, MAX_RANGE_WINDOWS, RangeSource, RangeWindow};

pub use canny::{Canny, EDGE};

/// Camera geometry needed to turn disparity into distance at one resolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthModel {
    /// Focal length at this resolution, px.
    pub focal_px: f64,
    /// Baseline, metres.
    pub baseline_m: f64,
}

impl DepthModel {
    /// Distance along the optical axis for a disparity in px: `f * b / d`.
    pub fn range_m(&self, disparity_px: f64) -> f64 {
        self.focal_px * self.baseline_m / disparity_px
    }
}

/// Keeps the disparity only at edge pixels (the reference's "fused map"): `fused[i]` is
/// `disparity_q8[i]` where `edges[i]` is an edge, else 0. Returns (edge pixels, edge pixels
/// with a valid disparity).
pub fn fuse(edges: &[u8], disparity_q8: &[u16], fused_q8: &mut [u16]) -> (u32, u32) {
    let mut edge_px = 0;
    let mut valid = 0;
    for ((f, &e), &d) in fused_q8.iter_mut().zip(edges).zip(disparity_q8) {
        if e == EDGE {
            edge_px += 1;
            *f = d;
            if d != 0 {
                valid += 1;
            }
        } else {
            *f = 0;
        }
    }
    (edge_px, valid)
}

/// Ranges of the fused map over `window_count` equal vertical windows, left to right.
#[derive(Debug, Default)]
pub struct WindowRanger {
    ranges: Vec<Vec<f32>>,
}

impl WindowRanger {
    /// Creates a ranger.
    pub fn new() -> Self {
        Self::default()
    }

    /// Computes each window's ranges from a fused disparity map (`width x height`, 1/256 px,
    /// 0 = no data). `statistic` picks `range_m`; `mean_m` (the reference) and `near_m` (10th
    /// percentile: the nearest obstacle) are always filled.
    pub fn compute(
        &mut self,
        fused_q8: &[u16],
        width: usize,
        window_count: usize,
        depth: DepthModel,
        statistic: RangeStatistic,
        source: RangeSource,
    ) -> [RangeWindow; MAX_RANGE_WINDOWS] {
        let window_count = window_count.clamp(1, MAX_RANGE_WINDOWS);
        self.ranges.resize_with(window_count, Vec::new);
        self.ranges.iter_mut().for_each(Vec::clear);
        for row in fused_q8.chunks_exact(width) {
            for (x, &d) in row.iter().enumerate() {
                if d != 0 {
                    let w = x * window_count / width;
                    let range = depth.range_m(d as f64 / DISPARITY_SCALE as f64);
                    self.ranges[w].push(range as f32);
                }
            }
        }
        let mut out = [RangeWindow::default(); MAX_RANGE_WINDOWS];
        for (slot, ranges) in out.iter_mut().zip(self.ranges.iter_mut()) {
            if ranges.is_empty() {
                continue;
            }
            ranges.sort_unstable_by(f32::total_cmp);
            let n = ranges.len();
            let mean = ranges.iter().map(|&r| r as f64).sum::<f64>() / n as f64;
            let median = ranges[n / 2];
            let near = ranges[n / 10];
            *slot = RangeWindow {
                range_m: match statistic {
                    RangeStatistic::Mean => mean as f32,
                    RangeStatistic::Median => median,
                },
                near_m: near,
                mean_m: mean as f32,
                valid_px: n as u32,
                // Saturates with the evidence: 50 pixels give 0.5, 200 give 0.8.
                confidence: n as f32 / (n as f32 + 50.0),
                source: source as u32,
            };
        }
        out
    }
}

/// Merges the fast path's windows with a fresh long-range result: a window the fast path has
/// no data for takes the long-range value.
pub fn merge_windows(
    lo: &[RangeWindow; MAX_RANGE_WINDOWS],
    hi: Option<&[RangeWindow; MAX_RANGE_WINDOWS]>,
) -> [RangeWindow; MAX_RANGE_WINDOWS] {
    let mut out = *lo;
    if let Some(hi) = hi {
        for (o, h) in out.iter_mut().zip(hi) {
            if o.valid_px == 0 && h.valid_px > 0 {
                *o = *h;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEPTH: DepthModel = DepthModel {
        focal_px: 320.0,
        baseline_m: 0.06,
    };

    #[test]
    fn range_is_f_b_over_d() {
        assert!((DEPTH.range_m(19.2) - 1.0).abs() < 1e-9);
        assert!((DEPTH.range_m(9.6) - 2.0).abs() < 1e-9);
    }

    #[test]
    fn fuse_keeps_disparity_at_edges_only() {
        let edges = [EDGE, 0, EDGE, EDGE];
        let disp = [100, 200, 0, 300];
        let mut fused = [9u16; 4];
        assert_eq!(fuse(&edges, &disp, &mut fused), (3, 2));
        assert_eq!(fused, [100, 0, 0, 300]);
    }

    #[test]
    fn windows_split_columns_and_report_statistics() {
        let width = 9;
        // Three windows of 3 columns; disparities 19.2 px (1 m), 9.6 px (2 m), none.
        let mut fused = vec![0u16; width * 2];
        for y in 0..2 {
            for x in 0..3 {
                fused[y * width + x] = (19.2 * 256.0) as u16;
            }
            fused[y * width + 4] = (9.6 * 256.0) as u16;
        }
        let w = WindowRanger::new().compute(
            &fused,
            width,
            3,
            DEPTH,
            RangeStatistic::Mean,
            RangeSource::Lo,
        );
        assert_eq!(w[0].valid_px, 6);
        assert!((w[0].range_m - 1.0).abs() < 0.01, "{:?}", w[0]);
        assert_eq!(w[1].valid_px, 2);
        assert!((w[1].mean_m - 2.0).abs() < 0.01);
        assert_eq!(w[1].source, RangeSource::Lo as u32);
        assert_eq!(w[2].valid_px, 0);
        assert_eq!(w[2].source, RangeSource::None as u32);
        assert_eq!(w[3], RangeWindow::default());
    }

    #[test]
    fn median_resists_an_outlier_the_mean_does_not() {
        let width = 5;
        let mut fused = vec![(19.2 * 256.0) as u16; width];
        fused[4] = 256; // 1 px disparity = 19.2 m: a gross mismatch
        let mut ranger = WindowRanger::new();
        let mean = ranger.compute(
            &fused,
            width,
            1,
            DEPTH,
            RangeStatistic::Mean,
            RangeSource::Lo,
        )[0];
        let median = ranger.compute(
            &fused,
            width,
            1,
            DEPTH,
            RangeStatistic::Median,
            RangeSource::Lo,
        )[0];
        assert!(mean.range_m > 4.0, "{mean:?}");
        assert!((median.range_m - 1.0).abs() < 0.01, "{median:?}");
    }

    #[test]
    fn merge_fills_only_empty_fast_path_windows() {
        let mut lo = [RangeWindow::default(); MAX_RANGE_WINDOWS];
        lo[0] = RangeWindow {
            range_m: 1.0,
            valid_px: 10,
            source: 1,
            ..Default::default()
        };
        let mut hi = [RangeWindow::default(); MAX_RANGE_WINDOWS];
        hi[0] = RangeWindow {
            range_m: 3.0,
            valid_px: 10,
            source: 2,
            ..Default::default()
        };
        hi[1] = RangeWindow {
            range_m: 4.0,
            valid_px: 10,
            source: 2,
            ..Default::default()
        };
        let m = merge_windows(&lo, Some(&hi));
        assert_eq!(m[0].range_m, 1.0);
        assert_eq!(m[1].range_m, 4.0);
        assert_eq!(m[1].source, RangeSource::Hi as u32);
        assert_eq!(merge_windows(&lo, None), lo);
    }
}
