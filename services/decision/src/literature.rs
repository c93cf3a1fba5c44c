//! The two literature policies the reference cites: mean estimation and threshold
//! estimation, on the fused windows.

use super::*;

/// Mean estimation (Kostavelis et al.): the disparity sum of each window (valid pixels times
/// their mean disparity `f b / mean range`, so `focal_b` = f * b of the path) says how much is
/// near; the window with the smallest sum is the freest direction.
pub fn mean_estimation(windows: [Option<&RangeWindow>; 3]) -> MotionCommand {
    let sum = |w: Option<&RangeWindow>| {
        w.filter(|w| w.valid_px > 0 && w.mean_m > 0.0)
            .map_or(0.0, |w| {
                w.valid_px as f64 / w.mean_m as f64
                    * if w.source == RangeSource::Hi as u32 {
                        2.0
                    } else {
                        1.0
                    }
            })
    };
    let [l, m, r] = windows.map(sum);
    if m <= l && m <= r {
        MotionCommand::Forward
    } else if l < r {
        MotionCommand::Left
    } else {
        MotionCommand::Right
    }
}

/// Threshold estimation: the middle window is blocked when at least `rate_pct` % of its
/// pixels are nearer than `near_limit_m` (the literature's "disparity above T"; with the
/// fusion stage's `near_percentile` equal to `rate_pct`, `near_m` below the limit is exactly
/// that test). Free: forward; blocked: toward the side with the larger mean range.
pub fn threshold_estimation(
    windows: [Option<&RangeWindow>; 3],
    near_limit_m: f64,
) -> MotionCommand {
    let valid = windows.map(|w| w.filter(|w| w.valid_px > 0));
    let blocked = valid[1].is_some_and(|w| (w.near_m as f64) < near_limit_m);
    if !blocked {
        return MotionCommand::Forward;
    }
    let mean = |w: Option<&RangeWindow>| w.map_or(f64::INFINITY, |w| w.mean_m as f64);
    let windows = valid;
    if mean(windows[0]) >= mean(windows[2]) {
        MotionCommand::Left
    } else {
        MotionCommand::Right
    }
}
