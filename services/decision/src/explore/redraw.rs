//! Re-drawing the grid after a heading found wrong (`[nav.redraw]`).
//!
//! A turn held by a wall the camera faces from inside its blind range turns dead reckoning
//! alone; the scan is too empty to align, so nothing notices, and the grid goes on being drawn
//! in the turned frame. When the walls' heading fix later pulls the heading back, the scans
//! after it land in the right frame on top of walls drawn in the wrong one (seed 13 of the
//! generated mazes: a 48-degree turn that never happened, the walls smeared by 0.2 m and 13
//! doorway touches). A pose graph would re-optimise every pose; the error here has one
//! cause at one place, so the correction is one rigid turn: the edits made to the grid since
//! the blind turn began are logged beside a copy of the grid taken then, and a large
//! correction that follows, the other way from the turn, re-draws them on the copy with
//! their positions turned by it about where the blind turn began and their headings by what
//! of it they had not had yet. The copy replaces the grid once every edit is re-drawn, and
//! the robot's position moves with it.
//!
//! Written here rather than taken from a SLAM crate: the grid, its edits and the frame are
//! the explorer's own, and the whole correction is one rotation of a log.

use std::collections::VecDeque;
use std::ops::Range;

use hvs_runtime::config::RedrawConfig;

use super::controller::wrap_rad;
use super::grid::{OccupancyGrid, ScanPoints};
use crate::local_map::CellState;
use crate::odometry::DeadReckonedPose;

/// One change made to the grid, kept so that it can be made again from a corrected pose.
#[derive(Debug, Clone)]
pub enum GridEdit {
    /// The robot's footprint cleared ([`OccupancyGrid::clear_footprint`]).
    Footprint {
        /// Where the robot stood.
        pose: DeadReckonedPose,
        /// Half the footprint's length, metres.
        half_length_m: f64,
        /// Half its width, metres.
        half_width_m: f64,
    },
    /// A scan added ([`OccupancyGrid::insert`]).
    Scan(ScanPoints),
    /// A bump marked ([`OccupancyGrid::mark_bump`]).
    Bump {
        /// Where the robot stood.
        pose: DeadReckonedPose,
        /// Robot-frame extent ahead, metres.
        ahead_m: (f64, f64),
        /// Robot-frame extent to the left, metres.
        left_m: (f64, f64),
    },
    /// The cells near a point forgotten ([`OccupancyGrid::forget_disc`]).
    Forget {
        /// The disc's centre, grid frame, metres.
        centre_m: (f64, f64),
        /// Its radius, metres.
        radius_m: f64,
        /// Occupied cells this near the centre are kept, metres.
        keep_occupied_m: f64,
    },
}

impl GridEdit {
    /// Makes the edit on `grid`.
    pub fn apply(&self, grid: &mut OccupancyGrid) {
        match self {
            GridEdit::Footprint {
                pose,
                half_length_m,
                half_width_m,
            } => grid.clear_footprint(pose, *half_length_m, *half_width_m),
            GridEdit::Scan(points) => grid.insert(points),
            GridEdit::Bump {
                pose,
                ahead_m,
                left_m,
            } => grid.mark_bump(pose, *ahead_m, *left_m),
            GridEdit::Forget {
                centre_m,
                radius_m,
                keep_occupied_m,
            } => grid.forget_disc(*centre_m, *radius_m, *keep_occupied_m),
        }
    }
}

/// One logged edit. A scan's points live in the log's pools: one allocation for the whole
/// log rather than two a frame (a log of 3000 edits freed one by one measured up to 10 ms).
#[derive(Debug, Clone)]
enum Logged {
    Footprint {
        pose: DeadReckonedPose,
        half_length_m: f64,
        half_width_m: f64,
    },
    Scan {
        camera: (f64, f64),
        hits: Range<usize>,
        rays: Range<usize>,
    },
    Bump {
        pose: DeadReckonedPose,
        ahead_m: (f64, f64),
        left_m: (f64, f64),
    },
    Forget {
        centre_m: (f64, f64),
        radius_m: f64,
        keep_occupied_m: f64,
    },
}

/// The logged edits and their scans' points.
#[derive(Debug, Clone, Default)]
struct EditLog {
    /// Each edit with the heading corrections made since the log opened when it was made.
    edits: Vec<(f64, Logged)>,
    hits: Vec<(f64, f64)>,
    rays: Vec<((f64, f64), f64)>,
    /// A scan being re-drawn.
    scratch: Option<ScanPoints>,
}

impl EditLog {
    fn push(&mut self, corrected_rad: f64, edit: &GridEdit) {
        let logged = match edit {
            GridEdit::Footprint {
                pose,
                half_length_m,
                half_width_m,
            } => Logged::Footprint {
                pose: *pose,
                half_length_m: *half_length_m,
                half_width_m: *half_width_m,
            },
            GridEdit::Bump {
                pose,
                ahead_m,
                left_m,
            } => Logged::Bump {
                pose: *pose,
                ahead_m: *ahead_m,
                left_m: *left_m,
            },
            GridEdit::Forget {
                centre_m,
                radius_m,
                keep_occupied_m,
            } => Logged::Forget {
                centre_m: *centre_m,
                radius_m: *radius_m,
                keep_occupied_m: *keep_occupied_m,
            },
            GridEdit::Scan(points) => {
                let (h, r) = (self.hits.len(), self.rays.len());
                self.hits.extend_from_slice(&points.hits);
                self.rays.extend_from_slice(&points.rays);
                Logged::Scan {
                    camera: points.camera,
                    hits: h..self.hits.len(),
                    rays: r..self.rays.len(),
                }
            }
        };
        self.edits.push((corrected_rad, logged));
    }

    fn len(&self) -> usize {
        self.edits.len()
    }

    /// The stride over the logged scans that scores at most `max_scans` of them.
    fn scan_stride(&self, max_scans: usize) -> usize {
        let scans = self
            .edits
            .iter()
            .filter(|(_, e)| matches!(e, Logged::Scan { .. }))
            .count();
        scans.div_ceil(max_scans.max(1)).max(1)
    }

    /// How well the logged scans' points, placed as a re-draw by `turn_rad` would place
    /// them, agree with `grid` (the copy taken before the blind turn): points on occupied
    /// cells less points on free ones, and the points on cells either way. Every
    /// `redraw.scan_stride`th scan of the log as it was when the search began.
    fn agreement(&self, redraw: &Redraw, turn_rad: f64, grid: &OccupancyGrid) -> (i64, usize) {
        let turn = RigidTurn::new(redraw.pivot_m, turn_rad);
        let logged = &self.edits[..redraw.searched_edits.min(self.edits.len())];
        let (mut score, mut decided) = (0i64, 0usize);
        let scan_edits = logged
            .iter()
            .enumerate()
            .filter_map(|(i, (at, e))| match e {
                Logged::Scan { camera, hits, .. } => Some((i, *at, *camera, hits.clone())),
                _ => None,
            })
            .step_by(redraw.scan_stride);
        for (i, at, camera, hits) in scan_edits {
            let view_rad = turn_rad - redraw.had_rad(i, at);
            let seen_from = turn.point(camera);
            let (s, c) = view_rad.sin_cos();
            for p in &self.hits[hits] {
                let (dx, dy) = (p.0 - camera.0, p.1 - camera.1);
                let q = (seen_from.0 + dx * c - dy * s, seen_from.1 + dx * s + dy * c);
                match grid.state_at(q.0, q.1) {
                    CellState::Occupied => {
                        score += 1;
                        decided += 1;
                    }
                    CellState::Free => {
                        score -= 1;
                        decided += 1;
                    }
                    CellState::Unknown => {}
                }
            }
        }
        (score, decided)
    }

    /// Makes edit `i` on `grid` from the corrected pose: its position moved by `turn`, its
    /// view turned by `view_rad` about that position.
    fn redraw(&mut self, i: usize, turn: &RigidTurn, view_rad: f64, grid: &mut OccupancyGrid) {
        let pose = |p: &DeadReckonedPose| {
            let (x_m, y_m) = turn.point((p.x_m, p.y_m));
            DeadReckonedPose {
                x_m,
                y_m,
                heading_rad: p.heading_rad + view_rad,
            }
        };
        match &self.edits[i].1 {
            Logged::Footprint {
                pose: p,
                half_length_m,
                half_width_m,
            } => grid.clear_footprint(&pose(p), *half_length_m, *half_width_m),
            Logged::Bump {
                pose: p,
                ahead_m,
                left_m,
            } => grid.mark_bump(&pose(p), *ahead_m, *left_m),
            Logged::Forget {
                centre_m,
                radius_m,
                keep_occupied_m,
            } => {
                grid.forget_disc(turn.point(*centre_m), *radius_m, *keep_occupied_m);
            }
            Logged::Scan { camera, hits, rays } => {
                let seen_from = turn.point(*camera);
                let (s, c) = view_rad.sin_cos();
                let rot = |(x, y): (f64, f64)| (x * c - y * s, x * s + y * c);
                let scan = self.scratch.get_or_insert_with(|| ScanPoints {
                    camera: seen_from,
                    hits: Vec::new(),
                    rays: Vec::new(),
                });
                scan.camera = seen_from;
                scan.hits.clear();
                scan.hits.extend(self.hits[hits.clone()].iter().map(|p| {
                    let (dx, dy) = rot((p.0 - camera.0, p.1 - camera.1));
                    (seen_from.0 + dx, seen_from.1 + dy)
                }));
                scan.rays.clear();
                scan.rays
                    .extend(self.rays[rays.clone()].iter().map(|&(d, r)| (rot(d), r)));
                grid.insert(scan);
            }
        }
    }
}

/// What a re-draw turns: the grid frame about `pivot_m` by the heading found, each edit's
/// view by that less what of the jump it had already had.
#[derive(Debug, Clone, Copy)]
struct Redraw {
    pivot_m: (f64, f64),
    /// The corrections' sum when the jump began.
    base_rad: f64,
    /// The first edit logged during the jump.
    from_edit: usize,
    /// The edits the search scores: those logged before it began (the same scans for
    /// every turn tried, over the frames the search takes).
    searched_edits: usize,
    /// Every this many of those edits' scans are scored (at most `match_max_scans`).
    scan_stride: usize,
}

impl Redraw {
    /// What of the jump edit `i`, logged at corrections' sum `at_rad`, had had.
    fn had_rad(&self, i: usize, at_rad: f64) -> f64 {
        if i < self.from_edit {
            0.0
        } else {
            at_rad - self.base_rad
        }
    }
}

/// A rotation of the grid frame about a point.
#[derive(Debug, Clone, Copy)]
struct RigidTurn {
    pivot_m: (f64, f64),
    sin: f64,
    cos: f64,
}

impl RigidTurn {
    fn new(pivot_m: (f64, f64), rad: f64) -> Self {
        let (sin, cos) = rad.sin_cos();
        Self { pivot_m, sin, cos }
    }

    fn point(&self, (x, y): (f64, f64)) -> (f64, f64) {
        let (dx, dy) = (x - self.pivot_m.0, y - self.pivot_m.1);
        (
            self.pivot_m.0 + dx * self.cos - dy * self.sin,
            self.pivot_m.1 + dx * self.sin + dy * self.cos,
        )
    }
}

/// Dead reckoning's turn summed frame by frame while the scan is too empty to align (a
/// blind turn): the log's arc here, the arc searched by `scan_match::align_over_arc`.
#[derive(Debug, Clone, Copy)]
pub struct BlindArc {
    last_heading_rad: f64,
    turned_rad: f64,
}

impl BlindArc {
    /// An arc starting at `heading_rad`.
    pub fn new(heading_rad: f64) -> Self {
        Self {
            last_heading_rad: heading_rad,
            turned_rad: 0.0,
        }
    }

    /// Adds the turn to `heading_rad` and returns the sum, radians.
    pub fn advance(&mut self, heading_rad: f64) -> f64 {
        self.turned_rad += wrap_rad(heading_rad - self.last_heading_rad);
        self.last_heading_rad = heading_rad;
        self.turned_rad
    }

    /// The sum so far, radians.
    pub fn turned_rad(&self) -> f64 {
        self.turned_rad
    }
}

/// Where the log stands.
#[derive(Debug, Clone)]
enum Phase {
    /// The scan is too empty to align: dead reckoning's turn since is summed.
    Blind(BlindArc),
    /// The blind turn was large: a correction the other way is waited for.
    Waiting { turned_rad: f64 },
    /// A jump the other way came: the turns about it are scored against the copy,
    /// `turns_per_frame` a frame; `next` counts the turns scored (no turn first).
    Searching {
        turned_rad: f64,
        redraw: Redraw,
        /// The jump, radians.
        jump_rad: f64,
        /// No turn's agreement.
        still: i64,
        /// The best turn so far: agreement, points decided, turn.
        best: Option<(i64, usize, f64)>,
        next: usize,
        /// Time spent scoring so far (the debug log's `search_us`), nanoseconds.
        spent_ns: u64,
    },
    /// Re-drawing the log on the copy: `next` edits done. The edits logged before the
    /// jump began (`from_edit`) turn by all of it; those logged during it by what of it
    /// they had not had yet (`corrected_rad` then less `base_rad`); those logged from now
    /// on (at `frozen_rad`) are in the jump's heading and get the position's turn and the
    /// difference between the turn found and the jump.
    Redrawing {
        redraw: Redraw,
        turn: RigidTurn,
        turn_rad: f64,
        /// The heading correction the re-drawn grid needs beyond the jump.
        dheading_rad: f64,
        frozen_rad: f64,
        next: usize,
    },
}

/// The log of the grid's edits since a blind turn began, and the copy of the grid then.
#[derive(Debug, Clone)]
pub struct RedrawLog {
    cfg: RedrawConfig,
    copy: OccupancyGrid,
    pivot_m: (f64, f64),
    opened_ns: u64,
    /// Heading corrections made since the log opened, radians.
    corrected_rad: f64,
    /// `corrected_rad` at the last frame.
    last_corrected_rad: f64,
    /// Per frame within `jump_window_s`: the time, `corrected_rad` and the edits logged.
    recent: VecDeque<(u64, f64, usize)>,
    /// The edits, each with `corrected_rad` when it was made.
    edits: EditLog,
    phase: Phase,
}

/// What a frame's step of the log did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RedrawStep {
    /// Nothing to tell: keep the log.
    Keep,
    /// The log has nothing to correct: drop it.
    Drop,
    /// The copy is re-drawn: it replaces the grid, and the pose moves by this.
    Done {
        /// Position change, metres.
        dx_m: f64,
        /// Position change, metres.
        dy_m: f64,
        /// Heading change beyond the jump already made, radians.
        dheading_rad: f64,
    },
}

impl RedrawLog {
    /// Opens a log at `pose`, the first frame whose scan cannot be aligned, with a copy of
    /// `grid` as it is before this frame's edits, made in `spare` (a grid of the same size
    /// whose memory is reused) when given.
    pub fn open(
        cfg: RedrawConfig,
        grid: &OccupancyGrid,
        spare: Option<OccupancyGrid>,
        pose: &DeadReckonedPose,
        now_ns: u64,
    ) -> Self {
        let copy = match spare {
            Some(mut spare) => {
                spare.copy_from(grid);
                spare
            }
            None => grid.clone(),
        };
        Self {
            cfg,
            copy,
            pivot_m: (pose.x_m, pose.y_m),
            opened_ns: now_ns,
            corrected_rad: 0.0,
            last_corrected_rad: 0.0,
            recent: VecDeque::new(),
            edits: EditLog::default(),
            phase: Phase::Blind(BlindArc::new(pose.heading_rad)),
        }
    }

    /// Counts a heading correction made to the pose, radians.
    pub fn corrected(&mut self, dheading_rad: f64) {
        self.corrected_rad += dheading_rad;
    }

    /// Logs an edit made to the live grid.
    pub fn log(&mut self, edit: &GridEdit) {
        let at = match self.phase {
            Phase::Redrawing { frozen_rad, .. } => frozen_rad,
            _ => self.corrected_rad,
        };
        self.edits.push(at, edit);
    }

    /// Whether the copy is being re-drawn.
    pub fn redrawing(&self) -> bool {
        matches!(self.phase, Phase::Redrawing { .. })
    }

    /// One frame, before its edits: `alignable` whether this frame's scan has points enough
    /// to align, `position` the pose's position now. With [`RedrawStep::Done`] take the copy
    /// with [`RedrawLog::into_grid`].
    pub fn step(&mut self, pose: &DeadReckonedPose, alignable: bool, now_ns: u64) -> RedrawStep {
        let frame_rad = self.corrected_rad - self.last_corrected_rad;
        self.last_corrected_rad = self.corrected_rad;
        let window_ns = (self.cfg.jump_window_s * 1e9) as u64;
        while self
            .recent
            .front()
            .is_some_and(|&(t, ..)| now_ns.saturating_sub(t) > window_ns)
        {
            self.recent.pop_front();
        }
        self.recent
            .push_back((now_ns, self.corrected_rad, self.edits.len()));
        // Until a re-draw is searched for, the log is kept `window_s` at most: a scan that
        // stays empty (the robot facing a wall, or blind in a dark room), or a correction
        // that never comes, must not grow it without end.
        let waiting = matches!(self.phase, Phase::Blind(_) | Phase::Waiting { .. });
        if waiting && super::elapsed_s(self.opened_ns, now_ns) > self.cfg.window_s {
            return RedrawStep::Drop;
        }
        match &mut self.phase {
            Phase::Blind(arc) => {
                let turned_rad = arc.advance(pose.heading_rad);
                if !alignable {
                    return RedrawStep::Keep;
                }
                if turned_rad.abs() < self.cfg.blind_turn_deg.to_radians() {
                    return RedrawStep::Drop;
                }
                self.phase = Phase::Waiting { turned_rad };
                RedrawStep::Keep
            }
            Phase::Waiting { turned_rad } => {
                // Only a jump: the corrections of ordinary drift add up to tens of degrees
                // over minutes (measured: 86 degrees in 120 s on generated maze 2) and say
                // nothing about the blind turn.
                let Some(&(_, base_rad, from_edit)) = self.recent.front() else {
                    return RedrawStep::Keep;
                };
                let c = self.corrected_rad - base_rad;
                // A held turn left dead reckoning ahead in the turn's direction: the
                // correction that undoes it goes the other way.
                let undoes = c * *turned_rad < 0.0;
                if !(undoes
                    && c.abs() >= self.cfg.min_correction_deg.to_radians()
                    && frame_rad.abs() < self.cfg.settled_deg.to_radians())
                {
                    return RedrawStep::Keep;
                }
                self.phase = Phase::Searching {
                    turned_rad: *turned_rad,
                    redraw: Redraw {
                        pivot_m: self.pivot_m,
                        base_rad,
                        from_edit,
                        searched_edits: self.edits.len(),
                        scan_stride: self.edits.scan_stride(self.cfg.match_max_scans as usize),
                    },
                    jump_rad: c,
                    still: 0,
                    best: None,
                    next: 0,
                    spent_ns: 0,
                };
                self.search()
            }
            Phase::Searching { .. } => self.search(),
            Phase::Redrawing {
                redraw,
                turn,
                turn_rad,
                dheading_rad,
                next,
                ..
            } => {
                let end = (*next + self.cfg.edits_per_frame as usize).min(self.edits.len());
                for i in *next..end {
                    let at = self.edits.edits[i].0;
                    let view_rad = *turn_rad - redraw.had_rad(i, at);
                    self.edits.redraw(i, turn, view_rad, &mut self.copy);
                }
                *next = end;
                if end < self.edits.len() {
                    return RedrawStep::Keep;
                }
                let (x, y) = turn.point((pose.x_m, pose.y_m));
                RedrawStep::Done {
                    dx_m: x - pose.x_m,
                    dy_m: y - pose.y_m,
                    dheading_rad: *dheading_rad,
                }
            }
        }
    }

    /// Scores up to `turns_per_frame` turns of the search; once all are scored, drops the
    /// log or starts re-drawing it with the best.
    fn search(&mut self) -> RedrawStep {
        let Phase::Searching {
            turned_rad,
            redraw,
            jump_rad,
            still,
            best,
            next,
            spent_ns,
        } = &mut self.phase
        else {
            return RedrawStep::Keep;
        };
        let started = std::time::Instant::now();
        // The jump brings the heading to the building's axes; the turn that brings
        // the scans since the blind turn onto the grid drawn before it is searched
        // about it, and must fit that grid better than no turn at all (a blind
        // turn that was made, followed by the fix of an older error, measured on
        // generated maze 6, must not move the scans).
        let step = self.cfg.search_step_deg.to_radians();
        let n = (self.cfg.search_deg / self.cfg.search_step_deg).floor() as usize;
        let turns = 2 * n + 2;
        for _ in 0..self.cfg.turns_per_frame {
            if *next >= turns {
                break;
            }
            if *next == 0 {
                *still = self.edits.agreement(redraw, 0.0, &self.copy).0;
            } else {
                let k = (*next - 1) as f64 - n as f64;
                let turn_rad = *jump_rad + k * step;
                let (score, decided) = self.edits.agreement(redraw, turn_rad, &self.copy);
                // The last of equal scores, as `max_by_key` takes.
                if best.is_none_or(|(b, ..)| score >= b) {
                    *best = Some((score, decided, turn_rad));
                }
            }
            *next += 1;
        }
        *spent_ns += u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        if *next < turns {
            return RedrawStep::Keep;
        }
        tracing::debug!(
            jump_deg = jump_rad.to_degrees(),
            edits = redraw.searched_edits,
            still_agreement = *still,
            turns,
            search_us = *spent_ns / 1000,
            best = ?best.map(|(score, decided, rad)| (score, decided, rad.to_degrees())),
            "redraw: a heading jump after a blind turn, turns searched"
        );
        let Some((score, decided, turn_rad)) = *best else {
            return RedrawStep::Drop;
        };
        // The turn found must be as large as the jump that asked for it: a small one
        // says the scans since the blind turn were drawn in the grid's frame, and the
        // jump fixed drift (measured on generated maze 18: a 15-degree jump, the
        // best turn 1 degree).
        // And it must undo the blind turn too (with `search_deg` wider than the jump
        // the search reaches the other side).
        let gain = (score - *still) as f64;
        if decided < self.cfg.match_min_points as usize
            || gain < self.cfg.match_min_gain_share * decided as f64
            || turn_rad.abs() < self.cfg.min_correction_deg.to_radians()
            || turn_rad * *turned_rad >= 0.0
        {
            return RedrawStep::Drop;
        }
        // The pose has had the corrections made since the jump began, those of the
        // search's frames too.
        let had_rad = self.corrected_rad - redraw.base_rad;
        self.phase = Phase::Redrawing {
            redraw: *redraw,
            turn: RigidTurn::new(self.pivot_m, turn_rad),
            turn_rad,
            dheading_rad: turn_rad - had_rad,
            frozen_rad: self.corrected_rad,
            next: 0,
        };
        RedrawStep::Keep
    }

    /// The copy: re-drawn after [`RedrawStep::Done`], otherwise as it was taken (memory to
    /// reuse).
    pub fn into_grid(self) -> OccupancyGrid {
        self.copy
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvs_runtime::config::GridConfig;

    const FRAME_NS: u64 = 66_666_667;

    fn pose(x_m: f64, y_m: f64, heading_deg: f64) -> DeadReckonedPose {
        DeadReckonedPose {
            x_m,
            y_m,
            heading_rad: heading_deg.to_radians(),
        }
    }

    /// One frame standing at the origin facing `heading_deg`, frame number `frame`.
    fn step_at(log: &mut RedrawLog, heading_deg: f64, alignable: bool, frame: u64) -> RedrawStep {
        log.step(&pose(0.0, 0.0, heading_deg), alignable, frame * FRAME_NS)
    }

    /// A scan of a wall across the view `ahead_m` in front of the camera at `p`, drawn as
    /// dead reckoning would place it.
    fn wall_ahead(p: &DeadReckonedPose, ahead_m: f64) -> ScanPoints {
        let (s, c) = p.heading_rad.sin_cos();
        let mut hits = Vec::new();
        let mut rays = Vec::new();
        for i in -10..=10 {
            let left = f64::from(i) * 0.05;
            hits.push((
                p.x_m + ahead_m * c - left * s,
                p.y_m + ahead_m * s + left * c,
            ));
            let len = (ahead_m * ahead_m + left * left).sqrt();
            rays.push((
                (
                    ahead_m / len * c - left / len * s,
                    ahead_m / len * s + left / len * c,
                ),
                len - 0.15,
            ));
        }
        ScanPoints {
            camera: (p.x_m, p.y_m),
            hits,
            rays,
        }
    }

    fn cfg() -> RedrawConfig {
        RedrawConfig {
            blind_turn_deg: 30.0,
            edits_per_frame: 2,
            turns_per_frame: 1000,
            ..RedrawConfig::default()
        }
    }

    /// Draws `n` scans of a wall `ahead_m` in front of `p` on `grid`, logging them when a
    /// log is given.
    fn draw(
        grid: &mut OccupancyGrid,
        mut log: Option<&mut RedrawLog>,
        p: &DeadReckonedPose,
        ahead_m: f64,
        n: usize,
    ) {
        for _ in 0..n {
            let edit = GridEdit::Scan(wall_ahead(p, ahead_m));
            edit.apply(grid);
            if let Some(log) = log.as_deref_mut() {
                log.log(&edit);
            }
        }
    }

    #[test]
    fn a_held_turn_undone_by_a_correction_redraws_the_walls_seen_since_where_they_are() {
        use crate::local_map::CellState::Occupied;
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let start = pose(0.0, 0.0, 0.0);
        // Before the turn: a wall 1 m east.
        draw(&mut grid, None, &start, 1.0, 4);
        let mut log = RedrawLog::open(cfg(), &grid, None, &start, 0);
        // Held by a wall: dead reckoning turns 40 degrees left, the robot does not.
        let mut now = 0;
        for deg in [10.0, 20.0, 30.0, 40.0] {
            now += FRAME_NS;
            assert_eq!(log.step(&pose(0.0, 0.0, deg), false, now), RedrawStep::Keep);
        }
        // The scan aligns again; the same wall is drawn 1 m along the dead-reckoned 40
        // degrees, four times.
        let wrong = pose(0.0, 0.0, 40.0);
        now += FRAME_NS;
        assert_eq!(log.step(&wrong, true, now), RedrawStep::Keep);
        draw(&mut grid, Some(&mut log), &wrong, 1.0, 4);
        let drawn = (40f64.to_radians().cos(), 40f64.to_radians().sin());
        assert_eq!(grid.state_at(drawn.0, drawn.1), Occupied);
        // The walls' fix pulls the heading back over two frames.
        log.corrected(-0.3);
        now += FRAME_NS;
        assert_eq!(log.step(&wrong, true, now), RedrawStep::Keep);
        log.corrected(-(40f64.to_radians() - 0.3));
        now += FRAME_NS;
        assert_eq!(
            log.step(&wrong, true, now),
            RedrawStep::Keep,
            "not settled yet"
        );
        // Settled: the next frame finds the turn, two edits a frame, done in the third.
        let here = pose(0.0, 0.0, 0.0);
        let mut steps = Vec::new();
        for _ in 0..4 {
            now += FRAME_NS;
            steps.push(log.step(&here, true, now));
        }
        assert_eq!(steps[..2], [RedrawStep::Keep, RedrawStep::Keep]);
        let RedrawStep::Done {
            dx_m,
            dy_m,
            dheading_rad,
        } = steps[2]
        else {
            panic!("re-drawn in two frames: {steps:?}");
        };
        // The robot stood at the pivot: it does not move, and the jump was the turn.
        assert!(dx_m.abs() < 1e-9 && dy_m.abs() < 1e-9);
        assert!(dheading_rad.abs() < 1e-9, "{dheading_rad}");
        let redrawn = log.into_grid();
        assert_eq!(redrawn.hits_at(1.0, 0.0), 2 * grid.hits_at(1.0, 0.0));
        assert_ne!(redrawn.state_at(drawn.0, drawn.1), Occupied);
    }

    #[test]
    fn a_position_driven_in_the_turned_frame_is_turned_back_about_the_pivot() {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let start = pose(1.0, 0.0, 0.0);
        // A wall 2 m east of the pivot.
        draw(&mut grid, None, &start, 2.0, 4);
        let mut log = RedrawLog::open(cfg(), &grid, None, &start, 0);
        assert_eq!(
            log.step(&pose(1.0, 0.0, 90.0), false, FRAME_NS),
            RedrawStep::Keep
        );
        // Driven 1 m "north" in the turned frame: truly 1 m east, the wall 1 m ahead.
        let wrong = pose(1.0, 1.0, 90.0);
        assert_eq!(log.step(&wrong, true, 2 * FRAME_NS), RedrawStep::Keep);
        draw(&mut grid, Some(&mut log), &wrong, 1.0, 4);
        log.corrected(-std::f64::consts::FRAC_PI_2);
        // The frame of the correction, then the one that finds it settled.
        for i in 3..5 {
            assert_eq!(
                log.step(&pose(1.0, 1.0, 0.0), true, i * FRAME_NS),
                RedrawStep::Keep
            );
        }
        let steps: Vec<_> = (5..8)
            .map(|i| log.step(&pose(1.0, 1.0, 0.0), true, i * FRAME_NS))
            .collect();
        match steps[1] {
            RedrawStep::Done { dx_m, dy_m, .. } => {
                assert!(
                    (dx_m - 1.0).abs() < 1e-9 && (dy_m + 1.0).abs() < 1e-9,
                    "{dx_m} {dy_m}"
                );
            }
            _ => panic!("{steps:?}"),
        }
    }

    #[test]
    fn a_correction_the_scans_do_not_fit_better_is_not_a_turn_undone() {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let start = pose(0.0, 0.0, 0.0);
        draw(&mut grid, None, &start, 1.0, 4);
        let mut log = RedrawLog::open(cfg(), &grid, None, &start, 0);
        // A turn truly made while blind: the wall it faces again is where the grid has it.
        assert_eq!(step_at(&mut log, 40.0, false, 1), RedrawStep::Keep);
        assert_eq!(step_at(&mut log, 0.0, false, 2), RedrawStep::Keep);
        assert_eq!(step_at(&mut log, 0.0, false, 3), RedrawStep::Keep);
        let back = pose(0.0, 0.0, 0.0);
        // Dead reckoning turned 40 degrees out and 40 back: the arc sums to nothing.
        assert_eq!(log.step(&back, true, 4 * FRAME_NS), RedrawStep::Drop);

        let mut log = RedrawLog::open(cfg(), &grid, None, &start, 0);
        assert_eq!(step_at(&mut log, 40.0, false, 1), RedrawStep::Keep);
        let turned = pose(0.0, 0.0, 40.0);
        assert_eq!(log.step(&turned, true, 2 * FRAME_NS), RedrawStep::Keep);
        draw(&mut grid, Some(&mut log), &turned, 1.0, 4);
        // The walls' fix pulls 20 degrees back (an older error): the scans drawn since fit
        // the grid as they are (unseen there: nothing to fit), so nothing is re-drawn.
        log.corrected(-20f64.to_radians());
        assert_eq!(log.step(&turned, true, 3 * FRAME_NS), RedrawStep::Keep);
        assert_eq!(log.step(&turned, true, 4 * FRAME_NS), RedrawStep::Drop);
    }

    #[test]
    fn drift_corrections_adding_up_over_minutes_are_not_a_jump() {
        let grid = OccupancyGrid::new(GridConfig::default());
        let mut log = RedrawLog::open(cfg(), &grid, None, &pose(0.0, 0.0, 0.0), 0);
        assert_eq!(step_at(&mut log, 45.0, false, 1), RedrawStep::Keep);
        assert_eq!(step_at(&mut log, 45.0, true, 2), RedrawStep::Keep);
        // 0.3 degrees a frame the other way: 86 degrees in 300 frames (20 s), 6.6 in a
        // jump window.
        for i in 3..303 {
            log.corrected(-0.005);
            assert_eq!(step_at(&mut log, 45.0, true, i), RedrawStep::Keep);
        }
        assert!(!log.redrawing());
        // A sum like it in one frame is a jump: examined once settled (and, with no scans
        // to fit to the grid, not taken).
        log.corrected(-0.3);
        assert_eq!(step_at(&mut log, 28.0, true, 303), RedrawStep::Keep);
        assert_eq!(step_at(&mut log, 28.0, true, 304), RedrawStep::Drop);
    }

    #[test]
    fn a_small_blind_turn_a_correction_the_same_way_or_an_old_log_is_dropped() {
        let grid = OccupancyGrid::new(GridConfig::default());
        let mut log = RedrawLog::open(cfg(), &grid, None, &pose(0.0, 0.0, 0.0), 0);
        assert_eq!(step_at(&mut log, 20.0, false, 1), RedrawStep::Keep);
        assert_eq!(step_at(&mut log, 20.0, true, 2), RedrawStep::Drop);

        let mut log = RedrawLog::open(cfg(), &grid, None, &pose(0.0, 0.0, 0.0), 0);
        assert_eq!(step_at(&mut log, 45.0, false, 1), RedrawStep::Keep);
        assert_eq!(step_at(&mut log, 45.0, true, 2), RedrawStep::Keep);
        // A correction further the way of the turn is not the turn undone.
        log.corrected(0.5);
        for i in 3..6 {
            assert_eq!(step_at(&mut log, 70.0, true, i), RedrawStep::Keep);
        }
        assert!(!log.redrawing());
        let late = (cfg().window_s * 1e9) as u64 + 10 * FRAME_NS;
        assert_eq!(
            log.step(&pose(0.0, 0.0, 70.0), true, late),
            RedrawStep::Drop
        );
    }

    /// The held turn of the first test with `cfg`: the frames from the settled jump to
    /// the end of the re-drawing, the last step and the re-drawn copy.
    fn held_turn_redrawn(cfg: RedrawConfig) -> (usize, RedrawStep, OccupancyGrid) {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let start = pose(0.0, 0.0, 0.0);
        draw(&mut grid, None, &start, 1.0, 4);
        let mut log = RedrawLog::open(cfg, &grid, None, &start, 0);
        let mut now = 0;
        for deg in [10.0, 20.0, 30.0, 40.0] {
            now += FRAME_NS;
            log.step(&pose(0.0, 0.0, deg), false, now);
        }
        let wrong = pose(0.0, 0.0, 40.0);
        now += FRAME_NS;
        log.step(&wrong, true, now);
        draw(&mut grid, Some(&mut log), &wrong, 1.0, 4);
        log.corrected(-40f64.to_radians());
        now += FRAME_NS;
        log.step(&wrong, true, now);
        let here = pose(0.0, 0.0, 0.0);
        for frames in 1..100 {
            now += FRAME_NS;
            let step = log.step(&here, true, now);
            if step != RedrawStep::Keep {
                return (frames, step, log.into_grid());
            }
        }
        panic!("not re-drawn in 100 frames");
    }

    #[test]
    fn a_search_spread_over_frames_finds_the_turn_found_in_one() {
        let one = RedrawConfig {
            turns_per_frame: 1000,
            ..cfg()
        };
        let spread = RedrawConfig {
            turns_per_frame: 3,
            ..cfg()
        };
        let (frames_one, done_one, grid_one) = held_turn_redrawn(one);
        let (frames_spread, done_spread, grid_spread) = held_turn_redrawn(spread);
        assert!(matches!(done_one, RedrawStep::Done { .. }), "{done_one:?}");
        assert_eq!(done_spread, done_one);
        // 16 turns (no turn and 2 x 7 + 1 about the jump), 3 a frame: 5 more frames.
        assert_eq!(frames_spread, frames_one + 5);
        assert_eq!(grid_spread.hits_at(1.0, 0.0), grid_one.hits_at(1.0, 0.0));
        let drawn = (40f64.to_radians().cos(), 40f64.to_radians().sin());
        assert_eq!(
            grid_spread.state_at(drawn.0, drawn.1),
            grid_one.state_at(drawn.0, drawn.1)
        );
    }

    #[test]
    fn a_blind_spell_longer_than_the_window_drops_its_log() {
        let grid = OccupancyGrid::new(GridConfig::default());
        let mut log = RedrawLog::open(cfg(), &grid, None, &pose(0.0, 0.0, 0.0), 0);
        let window_frames = (cfg().window_s * 1e9 / FRAME_NS as f64) as u64;
        let mut frame = 1;
        // Blind, turning slowly, for the whole window: the log is kept, and grows.
        while frame <= window_frames {
            assert_eq!(
                step_at(&mut log, frame as f64 * 0.01, false, frame),
                RedrawStep::Keep
            );
            log.log(&GridEdit::Scan(wall_ahead(&pose(0.0, 0.0, 0.0), 1.0)));
            frame += 1;
        }
        assert!(log.edits.len() as u64 >= window_frames);
        // Still blind past it: dropped, though the scan never came back.
        assert_eq!(
            step_at(&mut log, frame as f64 * 0.01, false, frame + 1),
            RedrawStep::Drop
        );
    }
}
