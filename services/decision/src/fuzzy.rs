//! Fuzzy wall memberships: a band around each threshold and the corridor rule.

use super::*;

/// Membership in [0, 1] of "wall" for each side.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Memberships {
    /// Wall on the left.
    pub left: f64,
    /// Wall in front.
    pub front: f64,
    /// Wall on the right.
    pub right: f64,
}

/// Fuzzy "nearer than `threshold`": 1 below `threshold * (1 - band)`, 0 above
/// `threshold * (1 + band)`, linear between (0.5 at the threshold); 0 without a range.
pub fn near_membership(range_m: Option<f64>, threshold_m: f64, band: f64) -> f64 {
    let Some(r) = range_m else { return 0.0 };
    let half = (threshold_m * band).max(1e-9);
    ((threshold_m + half - r) / (2.0 * half)).clamp(0.0, 1.0)
}

/// Wall memberships of one frame.
///
/// Each side is fuzzy "nearer than its threshold" (`a` for the sides, `b` in front, those
/// of the path the range came from). On top, the corridor rule: in a hallway the side
/// windows see the walls obliquely, so their ranges exceed `a` although the walls are right
/// there. When the front is open, both sides are nearer than the front (a wall converging
/// ahead; a side opening is farther than the front or not seen at all) and both are within
/// `corridor_factor * a`, both sides count as walls. This is what reconciles the thesis's
/// printed hallway example (2.675, 3.054, 2.910 ft: above `a` = 2.35 ft on both sides) with
/// its other seven examples, which crisp thresholds already classify.
pub fn fuzzy_memberships(r: &SideRanges, cfg: &DecisionConfig) -> Memberships {
    let t = |i: usize| r.thresholds(i, cfg);
    let band = cfg.fuzzy_band;
    let left = near_membership(r.left_m, t(0).side_m, band);
    let front = near_membership(r.middle_m, t(1).front_m, band);
    let right = near_membership(r.right_m, t(2).side_m, band);
    let corridor = match (r.left_m, r.right_m) {
        (Some(l), Some(rr)) => {
            // Nearer than the front by at least 3 % of it (an unseen front is far).
            let nearer = |x: f64| match r.middle_m {
                None => 1.0,
                Some(f) => ((f - x) / (0.03 * f).max(1e-9)).clamp(0.0, 1.0),
            };
            let within = |x: f64, i: usize| {
                near_membership(Some(x), t(i).side_m * cfg.corridor_factor, band)
            };
            (1.0 - front)
                .min(nearer(l))
                .min(nearer(rr))
                .min(within(l, 0))
                .min(within(rr, 2))
        }
        _ => 0.0,
    };
    Memberships {
        left: left.max(corridor),
        front,
        right: right.max(corridor),
    }
}
