//! The stall check: a robot pinned against a wall while its wheels are told to move sees the
//! same picture, but dead reckoning integrates the commands on, so the pose (and every scan
//! added from it) runs away from the truth. The camera is the only witness: when the scan
//! has not changed while dead reckoning says the robot moved far enough to change it, the
//! robot is stalled, and the pose is put back where the scan last changed.
//!
//! Written here rather than shared with the fuzzy policy's wedge detector, which watches its
//! three windows and acts on its own maneuvers; this one watches the scan bins the grid uses.

use hvs_runtime::config::StallConfig;
use hvs_shared::messages::{ObstacleScan, SCAN_BINS};

use super::controller::wrap_rad;
use crate::odometry::DeadReckonedPose;

/// The scan and pose where the picture last changed.
#[derive(Debug, Clone, Copy)]
struct Anchor {
    range_m: [f32; SCAN_BINS],
    pose: DeadReckonedPose,
}

/// Watches the scan against dead reckoning (its limits: `[nav.stall]`; the blind-turn limit
/// never fired over the 16 plain-wall maze runs, whose windows stay blind for longest, as
/// they kept 16 bins or more in view).
#[derive(Debug, Clone, Default)]
pub struct StallCheck {
    cfg: StallConfig,
    anchor: Option<Anchor>,
    /// The pose where the scan became too empty to compare, while it stays so.
    blind_from: Option<DeadReckonedPose>,
}

/// Median relative change between two scans over the bins in `bins` valid in both and
/// nearer than `max_m` (`None`: fewer than `min_bins`).
fn median_change(
    a: &[f32; SCAN_BINS],
    b: &[f32; SCAN_BINS],
    bins: std::ops::Range<usize>,
    max_m: f32,
    min_bins: usize,
) -> Option<f64> {
    let mut rel: Vec<f64> = a[bins.clone()]
        .iter()
        .zip(&b[bins])
        .filter(|&(&x, &y)| x > 0.0 && y > 0.0 && x < max_m && y < max_m)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).abs() / f64::from(x.min(y)))
        .collect();
    if rel.len() < min_bins {
        return None;
    }
    rel.sort_unstable_by(f64::total_cmp);
    Some(rel[rel.len() / 2])
}

impl StallCheck {
    /// A check with the limits of `cfg`.
    pub fn new(cfg: StallConfig) -> Self {
        Self {
            cfg,
            ..Self::default()
        }
    }

    /// Moves the remembered pose by a correction applied to dead reckoning this frame (the
    /// pose put back after a stall is then in the corrected frame).
    pub fn shift(&mut self, dx_m: f64, dy_m: f64, dheading_rad: f64) {
        for pose in self
            .anchor
            .as_mut()
            .map(|a| &mut a.pose)
            .into_iter()
            .chain(self.blind_from.as_mut())
        {
            pose.x_m += dx_m;
            pose.y_m += dy_m;
            pose.heading_rad += dheading_rad;
        }
    }

    /// Whether dead reckoning turned past `blind_turned_rad` while the scan showed too
    /// little to compare: then the pose where it went blind.
    fn blind_turn(
        &mut self,
        scan: &ObstacleScan,
        pose: &DeadReckonedPose,
    ) -> Option<DeadReckonedPose> {
        if scan.valid_bins() >= self.cfg.min_common_bins as usize {
            self.blind_from = None;
            return None;
        }
        let from = *self.blind_from.get_or_insert(*pose);
        (wrap_rad(pose.heading_rad - from.heading_rad).abs() >= self.cfg.blind_turned_rad)
            .then_some(from)
    }

    /// Feeds this frame's scan and dead-reckoned pose. Returns the pose where the picture last
    /// changed when the robot is stalled (the scan the same, dead reckoning moved or turned
    /// past the limits since), or where the scan went blind when dead reckoning turned past
    /// `blind_turned_rad` without it showing anything; the check then starts afresh from
    /// there.
    pub fn update(
        &mut self,
        scan: &ObstacleScan,
        pose: &DeadReckonedPose,
    ) -> Option<DeadReckonedPose> {
        if let Some(back) = self.blind_turn(scan, pose) {
            self.anchor = Some(Anchor {
                range_m: scan.range_m,
                pose: back,
            });
            return Some(back);
        }
        let Some(anchor) = self.anchor else {
            self.anchor = Some(Anchor {
                range_m: scan.range_m,
                pose: *pose,
            });
            return None;
        };
        // A turn changes every bin; a drive need not (a hallway's side walls read the same
        // ranges at the same bearings wherever the robot is along it), so a drive is judged
        // by the middle third, where a near wall can only be ahead.
        let all = median_change(
            &anchor.range_m,
            &scan.range_m,
            0..SCAN_BINS,
            f32::INFINITY,
            self.cfg.min_common_bins as usize,
        );
        let middle = median_change(
            &anchor.range_m,
            &scan.range_m,
            SCAN_BINS / 3..2 * SCAN_BINS / 3,
            self.cfg.middle_range_m as f32,
            self.cfg.min_common_middle_bins as usize,
        );
        let same_share = self.cfg.same_share;
        let same = |c: Option<f64>| c.is_some_and(|c| c < same_share);
        match all {
            Some(change) if change < same_share => {
                let moved = (pose.x_m - anchor.pose.x_m).hypot(pose.y_m - anchor.pose.y_m);
                let turned = wrap_rad(pose.heading_rad - anchor.pose.heading_rad).abs();
                if (moved >= self.cfg.moved_m && same(middle)) || turned >= self.cfg.turned_rad {
                    self.anchor = Some(Anchor {
                        range_m: scan.range_m,
                        pose: anchor.pose,
                    });
                    return Some(anchor.pose);
                }
                None
            }
            // Changed, or too little seen to tell: start from here.
            _ => {
                self.anchor = Some(Anchor {
                    range_m: scan.range_m,
                    pose: *pose,
                });
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(range_m: f32) -> ObstacleScan {
        ObstacleScan {
            tan_half_fov: 0.5,
            range_m: [range_m; SCAN_BINS],
            ..ObstacleScan::default()
        }
    }

    fn pose(x_m: f64, heading_deg: f64) -> DeadReckonedPose {
        DeadReckonedPose {
            x_m,
            y_m: 0.0,
            heading_rad: heading_deg.to_radians(),
        }
    }

    #[test]
    fn a_turn_that_leaves_the_picture_unchanged_is_a_stall_and_restores_the_pose() {
        let mut s = StallCheck::default();
        assert_eq!(s.update(&scan(0.8), &pose(0.0, 10.0)), None);
        // Dead reckoning turns on, the picture stays (1 % noise).
        assert_eq!(s.update(&scan(0.808), &pose(0.0, 20.0)), None);
        let back = s.update(&scan(0.792), &pose(0.0, 35.0));
        assert_eq!(back.map(|p| p.heading_rad.to_degrees().round()), Some(10.0));
    }

    #[test]
    fn a_picture_that_changes_with_the_motion_or_a_blind_one_is_no_stall() {
        let mut s = StallCheck::default();
        // Driving toward a wall 2 m ahead: 0.2 m nearer is 10 % nearer.
        for k in 0..10 {
            let x = 0.05 * f64::from(k);
            assert_eq!(s.update(&scan(2.0 - x as f32), &pose(x, 0.0)), None);
        }
        // Driving down a hallway whose side walls read the same at every step, with nothing
        // near ahead: no stall.
        let mut s = StallCheck::default();
        let mut hallway = scan(1.2);
        hallway.range_m[SCAN_BINS / 3..2 * SCAN_BINS / 3].fill(4.0);
        for k in 0..20 {
            assert_eq!(s.update(&hallway, &pose(0.05 * f64::from(k), 0.0)), None);
        }
        // A wall 1 m ahead that stays 1 m ahead while dead reckoning drives 0.2 m: a stall.
        let mut s = StallCheck::default();
        let stalled = (0..10).any(|k| {
            s.update(&scan(1.0), &pose(0.05 * f64::from(k), 0.0))
                .is_some()
        });
        assert!(stalled);
        // Blind (no bins) while driving, or turning less than a quarter turn: cannot tell,
        // no stall.
        let mut s = StallCheck::default();
        for k in 0..10 {
            assert_eq!(s.update(&scan(0.0), &pose(0.1 * f64::from(k), 0.0)), None);
        }
        for k in 0..9 {
            assert_eq!(s.update(&scan(0.0), &pose(1.0, f64::from(k) * 10.0)), None);
        }
        // Standing still with the same picture: no stall.
        let mut s = StallCheck::default();
        for _ in 0..10 {
            assert_eq!(s.update(&scan(1.0), &pose(0.0, 0.0)), None);
        }
    }

    #[test]
    fn a_turn_that_stays_blind_for_a_quarter_turn_is_held_and_restores_the_heading() {
        // Facing a wall nearer than the matcher's range, dead reckoning turns 7 degrees a
        // frame and nothing comes into view: held, put back to where it went blind.
        let mut s = StallCheck::default();
        assert_eq!(s.update(&scan(0.6), &pose(0.0, 0.0)), None);
        let back = (1..30)
            .find_map(|k| s.update(&scan(0.0), &pose(0.0, -40.0 - 7.0 * f64::from(k))))
            .expect("held");
        assert_eq!(back.heading_rad.to_degrees().round(), -47.0);
        // A turn that brings something into view before a quarter turn starts afresh.
        let mut s = StallCheck::default();
        for k in 0..40 {
            let seen = if k % 10 == 9 {
                0.8 + 0.1 * k as f32
            } else {
                0.0
            };
            assert_eq!(s.update(&scan(seen), &pose(0.0, 7.0 * f64::from(k))), None);
        }
    }

    #[test]
    fn heading_corrections_passed_on_are_not_taken_for_motion() {
        // Standing still while the walls' fix turns the heading by 6 degrees a frame: each
        // correction passed on with `shift` keeps the check quiet; the same heading change
        // without it is a stall.
        let mut s = StallCheck::default();
        let mut heading = 0.0;
        for _ in 0..10 {
            assert_eq!(s.update(&scan(1.0), &pose(0.0, heading)), None);
            heading += 6.0;
            s.shift(0.0, 0.0, 6f64.to_radians());
        }
        let mut s = StallCheck::default();
        let stalled = (0..10).any(|k| {
            s.update(&scan(1.0), &pose(0.0, 6.0 * f64::from(k)))
                .is_some()
        });
        assert!(stalled);
    }
}
