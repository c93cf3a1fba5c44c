//! What the decision stage tells an observer besides its decisions: the dead-reckoned pose
//! (`decision/pose`, every decision) and a window of the map it navigates by (`decision/map`,
//! a few times a second), for the live view and probes.

use hvs_shared::messages::{NAV_MAP_SIDE, NAV_MAP_UNKNOWN, NavMap, RobotPose};

use crate::Navigator;
use crate::local_map::CellState;

/// Cell edge of the published map, metres (the navigators' own grids use 0.1 m).
pub const NAV_MAP_CELL_M: f64 = 0.1;

/// The pose message of a decision.
pub fn pose_message(
    nav: &Navigator,
    frame_id: u64,
    capture_ns: u64,
    published_ns: u64,
) -> RobotPose {
    let p = nav.pose();
    RobotPose {
        frame_id,
        capture_ns,
        published_ns,
        x_m: p.x_m,
        y_m: p.y_m,
        heading_rad: p.heading_rad,
        distance_m: nav.distance_m(),
    }
}

/// Fills `out` with the navigator's map in a [`NAV_MAP_SIDE`]-cell square centred on the
/// robot (snapped to the cell grid, so that the cells do not shimmer as the robot moves).
pub fn fill_map(nav: &Navigator, now_ns: u64, out: &mut NavMap) {
    let p = nav.pose();
    let half = NAV_MAP_SIDE as f64 * 0.5;
    let origin_x = ((p.x_m / NAV_MAP_CELL_M).round() - half) * NAV_MAP_CELL_M;
    let origin_y = ((p.y_m / NAV_MAP_CELL_M).round() - half) * NAV_MAP_CELL_M;
    out.origin_x_m = origin_x;
    out.origin_y_m = origin_y;
    out.cell_m = NAV_MAP_CELL_M as f32;
    out.side = NAV_MAP_SIDE as u32;
    for (r, row) in out.cells.chunks_exact_mut(NAV_MAP_SIDE).enumerate() {
        let y = origin_y + (r as f64 + 0.5) * NAV_MAP_CELL_M;
        for (c, cell) in row.iter_mut().enumerate() {
            let x = origin_x + (c as f64 + 0.5) * NAV_MAP_CELL_M;
            *cell = match nav.map_state(x, y, now_ns) {
                CellState::Free => 0,
                CellState::Occupied => 100,
                CellState::Unknown => NAV_MAP_UNKNOWN,
            };
        }
    }
}
