//! hvs fusion: edges of the left image, the fused map (disparity kept at edge pixels only),
//! distances from disparities, and ranges over vertical windows, with no IPC.

pub mod canny;
pub mod pairing;

use hvs_runtime::config::{RangeStatistic, ScanFilter};
use hvs_shared::messages::{
    DISPARITY_SCALE, MAX_RANGE_WINDOWS, ObstacleScan, RangeSource, RangeWindow, SCAN_BINS,
    SCAN_SCATTERED,
};

pub use canny::{Canny, EDGE, sobel_edges};

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

/// How the windows' ranges are computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeParams {
    /// Number of equal vertical windows (1..=MAX_RANGE_WINDOWS).
    pub window_count: usize,
    /// Disparity to distance.
    pub depth: DepthModel,
    /// Statistic reported as `range_m`.
    pub statistic: RangeStatistic,
    /// Percentile reported as `near_m`, 0..=50.
    pub near_percentile: f64,
    /// Camera height above the floor, metres (level camera).
    pub camera_height_m: f64,
    /// Points below this height are floor (0 disables).
    pub min_height_m: f64,
    /// Points above this height are ignored (0 disables).
    pub max_height_m: f64,
    /// Points whose disparity confidence is below this (0..=255) are left out.
    pub min_confidence: u8,
    /// How the obstacle scan judges a bin's points.
    pub scan_filter: ScanFilter,
}

impl RangeParams {
    /// The parameters of a config at an image `width`.
    pub fn from_config(config: &hvs_runtime::config::HvsConfig, width: usize) -> Self {
        let f = &config.fusion;
        Self {
            window_count: f.windows as usize,
            depth: DepthModel {
                focal_px: config.camera.focal_px(width),
                baseline_m: config.camera.baseline_m,
            },
            statistic: f.statistic,
            near_percentile: f.near_percentile,
            camera_height_m: config.camera.height_m,
            min_height_m: f.min_height_m,
            max_height_m: f.max_height_m,
            min_confidence: (f.min_confidence.clamp(0.0, 1.0) * 255.0).round() as u8,
            scan_filter: f.scan_filter,
        }
    }
}

/// Ranges of the fused map over `window_count` equal vertical windows, left to right.
#[derive(Debug, Default)]
pub struct WindowRanger {
    ranges: Vec<Vec<f32>>,
    /// Per window: the sum of the kept points' confidence weights and of weight x range.
    weights: Vec<(f64, f64)>,
}

impl WindowRanger {
    /// Creates a ranger.
    pub fn new() -> Self {
        Self::default()
    }

    /// Computes each window's ranges from a fused disparity map (`width` columns, 1/256 px,
    /// 0 = no data). Points on the floor or above `max_height_m` are left out: a level camera
    /// at height `h` sees a pixel of row `v` with disparity `d` at height
    /// `h - (v - cy) * b / d` (the reference had no such filter: floor texture pulled its
    /// ranges down). `range_m` is the configured statistic; `mean_m` (the reference) and
    /// `near_m` (the near percentile) are always filled. With a `confidence` plane (one
    /// byte per pixel of the map), points below `p.min_confidence` are left out and the rest
    /// weigh by their confidence in `mean_m` and in the window's `confidence`; the
    /// percentiles and the median are over the points kept.
    pub fn compute(
        &mut self,
        fused_q8: &[u16],
        confidence: Option<&[u8]>,
        width: usize,
        p: &RangeParams,
        source: RangeSource,
    ) -> [RangeWindow; MAX_RANGE_WINDOWS] {
        let window_count = p.window_count.clamp(1, MAX_RANGE_WINDOWS);
        self.ranges.resize_with(window_count, Vec::new);
        self.ranges.iter_mut().for_each(Vec::clear);
        self.weights.clear();
        self.weights.resize(window_count, (0.0, 0.0));
        let confidence = confidence.filter(|c| c.len() == fused_q8.len());
        let height = fused_q8.len() / width.max(1);
        let cy = (height as f64 - 1.0) / 2.0;
        let b = p.depth.baseline_m;
        let fb = p.depth.focal_px * b;
        for (v, row) in fused_q8.chunks_exact(width).enumerate() {
            // Height of a point of this row = h - (v - cy) * b / d: floor and ceiling limits
            // become limits on d for the whole row.
            let dv = v as f64 - cy;
            for (x, &d) in row.iter().enumerate() {
                if d == 0 {
                    continue;
                }
                let d_px = d as f64 / DISPARITY_SCALE as f64;
                let height_m = p.camera_height_m - dv * b / d_px;
                if (p.min_height_m > 0.0 && height_m < p.min_height_m)
                    || (p.max_height_m > 0.0 && height_m > p.max_height_m)
                {
                    continue;
                }
                let weight = match confidence {
                    Some(c) => {
                        let c = c[v * width + x];
                        if c < p.min_confidence {
                            continue;
                        }
                        c as f64 / 255.0
                    }
                    None => 1.0,
                };
                let w = x * window_count / width;
                let range = fb / d_px;
                self.ranges[w].push(range as f32);
                let acc = &mut self.weights[w];
                acc.0 += weight;
                acc.1 += weight * range;
            }
        }
        let mut out = [RangeWindow::default(); MAX_RANGE_WINDOWS];
        for ((slot, ranges), &(weight, weighted)) in out
            .iter_mut()
            .zip(self.ranges.iter_mut())
            .zip(&self.weights)
        {
            if ranges.is_empty() || weight <= 0.0 {
                continue;
            }
            ranges.sort_unstable_by(f32::total_cmp);
            let n = ranges.len();
            let mean = weighted / weight;
            let pct = |q: f64| ranges[((n - 1) as f64 * q / 100.0).round() as usize];
            let near = pct(p.near_percentile);
            let trimmed = {
                let cut = n / 5;
                let mid = &ranges[cut..n - cut];
                mid.iter().map(|&r| r as f64).sum::<f64>() / mid.len() as f64
            };
            // Confidence: evidence (50 fully confident pixels give 0.5, 200 give 0.8) times
            // agreement (the interquartile range relative to the median).
            let spread = (pct(75.0) - pct(25.0)) as f64 / pct(50.0).max(1e-3) as f64;
            let evidence = weight / (weight + 50.0);
            *slot = RangeWindow {
                range_m: match p.statistic {
                    RangeStatistic::Mean => mean as f32,
                    RangeStatistic::Median => pct(50.0),
                    RangeStatistic::TrimmedMean => trimmed as f32,
                    RangeStatistic::Percentile => near,
                },
                near_m: near,
                mean_m: mean as f32,
                valid_px: n as u32,
                confidence: (evidence / (1.0 + spread)) as f32,
                source: source as u32,
            };
        }
        out
    }
}

/// Percentile of a scan bin's depths reported as its nearest obstacle: low enough to see a
/// thin obstacle, high enough that a few mismatched pixels do not raise a phantom.
pub const SCAN_PERCENTILE: f64 = 15.0;
/// Fewest points (after the height filter) a scan bin needs to report a range.
pub const SCAN_MIN_POINTS: usize = 6;
/// Share of an image column's points whose depth lies within [`SCAN_AGREE_FRACTION`] of a
/// depth for that depth to stand alone as the column's range (see [`agrees`]). A surface
/// nearer than the matcher's shortest range (`max_disp`) fills the picture with confident
/// false matches at scattered depths: measured in the simulator over 200 s from one start
/// pose, bins of such points had a median share of 0.23 (90th percentile 0.54) while 99 % of
/// the bins that saw a real wall had 0.76 or more, with textured and with plain walls
/// alike. Without the check a robot facing a wall closer than 0.35 m read it as open space
/// up to 9.6 m away. The test runs per column (a wall's end in front of a far wall splits a
/// bin by columns, and each column is one surface).
pub const SCAN_MIN_AGREEMENT: f64 = 0.6;
/// Share a nearer depth needs when the column's median depth agrees (a surface's top or
/// bottom edge in front of another: two surfaces, each a tight cluster).
pub const SCAN_MIN_NEAR_AGREEMENT: f64 = 0.2;
/// Relative depth difference within which a point agrees with a column's range (10 %: about
/// one pixel of disparity at 2 m).
pub const SCAN_AGREE_FRACTION: f32 = 0.1;

/// The obstacle scan of a disparity map: per column bin, a low percentile of the depths of
/// the points between the floor and ceiling limits; with [`ScanFilter::Agreement`], the
/// nearest of its image columns' such depths where the column's points agree on a surface
/// ([`SCAN_SCATTERED`] where none does). It uses the dense map, not the fused (edge-only)
/// one: the local map wants every bin filled, and the matcher's own texture and uniqueness
/// checks already removed most unreliable pixels.
#[derive(Debug, Default)]
pub struct ObstacleScanner {
    /// Depths per image column ([`ScanFilter::Agreement`]) or per bin.
    depths: Vec<Vec<f32>>,
    /// A bin's points pooled, for bins whose columns are each too sparse to judge.
    pool: Vec<f32>,
}

impl ObstacleScanner {
    /// Creates a scanner.
    pub fn new() -> Self {
        Self::default()
    }

    /// The scan of a disparity map of `width` columns (1/256 px, 0 = no data), with the
    /// height filter of `p`.
    /// Points whose `confidence` (when given) is below `p.min_confidence` are left out.
    pub fn compute(
        &mut self,
        disparity_q8: &[u16],
        confidence: Option<&[u8]>,
        width: usize,
        p: &RangeParams,
    ) -> ObstacleScan {
        // Per image column for the agreement test, per bin otherwise (no column split to
        // pool again on the default path).
        let per_column = p.scan_filter == ScanFilter::Agreement;
        self.depths
            .resize_with(if per_column { width } else { SCAN_BINS }, Vec::new);
        self.depths.iter_mut().for_each(Vec::clear);
        let mut scan = ObstacleScan {
            tan_half_fov: (width as f64 / 2.0 / p.depth.focal_px) as f32,
            ..ObstacleScan::default()
        };
        if width == 0 {
            return scan;
        }
        let height = disparity_q8.len() / width;
        let cy = (height as f64 - 1.0) / 2.0;
        let b = p.depth.baseline_m;
        let fb = p.depth.focal_px * b;
        for (v, row) in disparity_q8.chunks_exact(width).enumerate() {
            let dv = v as f64 - cy;
            // Height = h - dv * b / d: within [min, max] is a range of d for the whole row.
            let mut d_lo = 0.0f64;
            if dv > 0.0 && p.min_height_m > 0.0 {
                // Below the camera: height >= min  <=>  d >= dv * b / (h - min).
                let room = p.camera_height_m - p.min_height_m;
                if room <= 0.0 {
                    continue;
                }
                d_lo = dv * b / room;
            } else if dv < 0.0 && p.max_height_m > 0.0 {
                // Above: height <= max  <=>  d >= -dv * b / (max - h).
                let room = p.max_height_m - p.camera_height_m;
                if room <= 0.0 {
                    continue;
                }
                d_lo = -dv * b / room;
            }
            let lo_q8 = (d_lo * DISPARITY_SCALE as f64).ceil().max(1.0);
            if lo_q8 > u16::MAX as f64 {
                continue;
            }
            let lo_q8 = lo_q8 as u16;
            let conf_row = confidence
                .filter(|c| c.len() == disparity_q8.len())
                .map(|c| &c[v * width..(v + 1) * width]);
            for (x, &d) in row.iter().enumerate() {
                if d >= lo_q8 && conf_row.is_none_or(|c| c[x] >= p.min_confidence) {
                    let at = if per_column { x } else { x * SCAN_BINS / width };
                    self.depths[at].push((fb * DISPARITY_SCALE as f64 / d as f64) as f32);
                }
            }
        }
        for (bin, slot) in scan.range_m.iter_mut().enumerate() {
            if !per_column {
                let depths = &mut self.depths[bin];
                if depths.len() >= SCAN_MIN_POINTS
                    && let Some((range_m, _)) = percentile_depth(depths)
                {
                    *slot = range_m;
                }
                continue;
            }
            let columns = &mut self.depths[bin * width / SCAN_BINS..(bin + 1) * width / SCAN_BINS];
            // The nearest column that sees a surface; scattered if every column with enough
            // points scatters.
            let mut nearest: Option<f32> = None;
            let mut judged = 0usize;
            for depths in columns.iter_mut() {
                if depths.len() < SCAN_MIN_POINTS {
                    continue;
                }
                judged += 1;
                if let Some(r) = surface_range(depths) {
                    nearest = Some(nearest.map_or(r, |n| n.min(r)));
                }
            }
            *slot = match nearest {
                Some(r) => r,
                None if judged > 0 => SCAN_SCATTERED,
                None => {
                    // Every column too sparse to judge alone (a plain wall far away): the
                    // bin's points together.
                    self.pool.clear();
                    columns.iter().for_each(|c| self.pool.extend_from_slice(c));
                    if self.pool.len() < SCAN_MIN_POINTS {
                        continue;
                    }
                    surface_range(&mut self.pool).unwrap_or(SCAN_SCATTERED)
                }
            };
        }
        scan
    }
}

/// The [`SCAN_PERCENTILE`] depth of `depths` and its index once selected (`None`: empty).
fn percentile_depth(depths: &mut [f32]) -> Option<(f32, usize)> {
    let k = ((depths.len().checked_sub(1)?) as f64 * SCAN_PERCENTILE / 100.0).round() as usize;
    let (_, v, _) = depths.select_nth_unstable_by(k, f32::total_cmp);
    Some((*v, k))
}

/// The [`SCAN_PERCENTILE`] depth of `depths` if it lies on a surface (see [`agrees`]).
fn surface_range(depths: &mut [f32]) -> Option<f32> {
    let (range_m, k) = percentile_depth(depths)?;
    agrees(depths, range_m, k).then_some(range_m)
}

/// Whether a range `range_m` (the `k`-th of `depths`) is a surface rather than scattered
/// false matches: it holds [`SCAN_MIN_AGREEMENT`] of the points, or it holds
/// [`SCAN_MIN_NEAR_AGREEMENT`] and the median depth (a surface behind it) holds
/// [`SCAN_MIN_AGREEMENT`]. Measured per bin as in [`SCAN_MIN_AGREEMENT`], this keeps 99.5 %
/// of the bins on real walls and drops 90-95 % of the false-match bins.
fn agrees(depths: &mut [f32], range_m: f32, k: usize) -> bool {
    let share = |depths: &[f32], r: f32| {
        let tolerance = SCAN_AGREE_FRACTION * r;
        depths
            .iter()
            .filter(|&&d| (d - r).abs() <= tolerance)
            .count() as f64
            / depths.len().max(1) as f64
    };
    let near = share(depths, range_m);
    if near >= SCAN_MIN_AGREEMENT {
        return true;
    }
    if near < SCAN_MIN_NEAR_AGREEMENT {
        return false;
    }
    let m = depths.len() / 2;
    let (_, median, _) = depths.select_nth_unstable_by(m.max(k), f32::total_cmp);
    let median = *median;
    share(depths, median) >= SCAN_MIN_AGREEMENT
}

/// Fills the bins of the fast path's scan that have no data from a fresh long-range scan of
/// the same field of view (it sees farther: the fast path's disparity range ends at about
/// 2-10 m depending on `min_disp`).
pub fn merge_scans(lo: &ObstacleScan, hi: Option<&ObstacleScan>) -> ObstacleScan {
    let mut out = *lo;
    if let Some(hi) = hi {
        for (o, &h) in out.range_m.iter_mut().zip(&hi.range_m) {
            if *o <= 0.0 && h > 0.0 {
                *o = h;
                out.hi_bins += 1;
            }
        }
    }
    out
}

/// Edges, fused map and window ranges of one resolution, with its buffers: what the fusion
/// stage runs for every frame of a path.
#[derive(Debug)]
pub struct FusionPath {
    canny: Canny,
    ranger: WindowRanger,
    scanner: ObstacleScanner,
    scan: ObstacleScan,
    edges: Vec<u8>,
    fused: Vec<u16>,
    width: usize,
    height: usize,
    params: RangeParams,
    detector: hvs_runtime::config::EdgeDetector,
    low: u32,
    high: u32,
    source: RangeSource,
}

impl FusionPath {
    /// The path for `width x height` images of a config.
    pub fn new(
        config: &hvs_runtime::config::HvsConfig,
        width: usize,
        height: usize,
        source: RangeSource,
    ) -> Self {
        let f = &config.fusion;
        Self {
            canny: Canny::new(),
            ranger: WindowRanger::new(),
            scanner: ObstacleScanner::new(),
            scan: ObstacleScan::default(),
            edges: vec![0; width * height],
            fused: vec![0; width * height],
            width,
            height,
            params: RangeParams::from_config(config, width),
            detector: f.edges,
            low: f.canny_low,
            high: f.canny_high,
            source,
        }
    }

    /// Ranges of one frame: returns (windows, edge pixels, edge pixels with disparity).
    /// `left`, `disparity_q8` and `confidence` (the stereo stage's plane, if any) must hold
    /// `width * height` values.
    pub fn ranges(
        &mut self,
        left: &[u8],
        disparity_q8: &[u16],
        confidence: Option<&[u8]>,
    ) -> ([RangeWindow; MAX_RANGE_WINDOWS], u32, u32) {
        let (w, h) = (self.width, self.height);
        match self.detector {
            hvs_runtime::config::EdgeDetector::Canny => {
                self.canny
                    .detect(left, w, h, self.low, self.high, &mut self.edges);
            }
            hvs_runtime::config::EdgeDetector::Sobel => {
                sobel_edges(left, w, h, self.high, &mut self.edges);
            }
        }
        let (edge_px, valid) = fuse(&self.edges, disparity_q8, &mut self.fused);
        let windows = self
            .ranger
            .compute(&self.fused, confidence, w, &self.params, self.source);
        self.scan = self
            .scanner
            .compute(disparity_q8, confidence, w, &self.params);
        (windows, edge_px, valid)
    }

    /// The obstacle scan of the last frame (dense disparity, height-filtered).
    pub fn scan(&self) -> &ObstacleScan {
        &self.scan
    }

    /// The edge map of the last frame (`EDGE` = edge).
    pub fn edges(&self) -> &[u8] {
        &self.edges
    }

    /// The fused map of the last frame (disparity at edge pixels, 1/256 px).
    pub fn fused(&self) -> &[u16] {
        &self.fused
    }
}

/// Merges the fast path's windows with a fresh long-range result: a window where the fast
/// path has fewer than `min_valid_px` valid pixels (it cannot see beyond its disparity range,
/// about 2 m at 320x240) takes the long-range value when that one has more evidence. Each
/// window's `source` says which path it came from.
pub fn merge_windows(
    lo: &[RangeWindow; MAX_RANGE_WINDOWS],
    hi: Option<&[RangeWindow; MAX_RANGE_WINDOWS]>,
    min_valid_px: u32,
) -> [RangeWindow; MAX_RANGE_WINDOWS] {
    let mut out = *lo;
    if let Some(hi) = hi {
        for (o, h) in out.iter_mut().zip(hi) {
            if o.valid_px < min_valid_px && h.valid_px > o.valid_px {
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

    /// Windows over the whole map, no height filter.
    fn params(window_count: usize, statistic: RangeStatistic) -> RangeParams {
        RangeParams {
            window_count,
            depth: DEPTH,
            statistic,
            near_percentile: 10.0,
            camera_height_m: 0.25,
            min_height_m: 0.0,
            max_height_m: 0.0,
            min_confidence: 13,
            scan_filter: ScanFilter::Agreement,
        }
    }

    #[test]
    fn range_is_f_b_over_d() {
        assert!((DEPTH.range_m(19.2) - 1.0).abs() < 1e-9);
        assert!((DEPTH.range_m(9.6) - 2.0).abs() < 1e-9);
    }

    #[test]
    fn reference_profile_reproduces_the_printed_feet() {
        // f = 380 px, b = 0.1982 ft = 60.4 mm: distance_ft = 380 * 0.1982 / d.
        let reference = DepthModel {
            focal_px: 380.0,
            baseline_m: 0.1982 * hvs_runtime::config::M_PER_FT, // 60.41 mm
        };
        for d in [9.0, 25.5, 55.0] {
            let ft = reference.range_m(d) / hvs_runtime::config::M_PER_FT;
            assert!((ft - 380.0 * 0.1982 / d).abs() < 1e-3, "d {d}: {ft} ft");
        }
    }

    #[test]
    fn the_scan_sees_a_wall_per_column_and_leaves_out_the_floor() {
        // 64 columns (one per bin), 40 rows: a wall 1 m away in the left half, 2 m in the
        // right half, on every row above the middle; the rows below carry floor disparities
        // (a level camera 0.25 m up sees the floor at row offset dv with d = dv * b / h).
        let (w, h) = (64usize, 40usize);
        let mut disp = vec![0u16; w * h];
        let cy = (h as f64 - 1.0) / 2.0;
        for v in 0..h {
            for x in 0..w {
                let dv = v as f64 - cy;
                let d_px = if dv < 0.0 {
                    if x < 32 { 19.2 } else { 9.6 }
                } else {
                    dv * 0.06 / 0.25
                };
                disp[v * w + x] = (d_px * 256.0).round() as u16;
            }
        }
        let mut p = params(3, RangeStatistic::Median);
        p.min_height_m = 0.05;
        for filter in [ScanFilter::None, ScanFilter::Agreement] {
            p.scan_filter = filter;
            let scan = ObstacleScanner::new().compute(&disp, None, w, &p);
            assert!((scan.tan_half_fov - 32.0 / 320.0).abs() < 1e-6);
            for (i, &r) in scan.range_m.iter().enumerate() {
                let want = if i < 32 { 1.0 } else { 2.0 };
                assert!(
                    (r - want).abs() < 0.01,
                    "{filter:?} bin {i}: {r} m, want {want} m"
                );
            }
        }
        let scan = ObstacleScanner::new().compute(&disp, None, w, &p);
        // The floor alone is no obstacle.
        let mut floor_only = disp.clone();
        floor_only[..w * h / 2].fill(0);
        assert_eq!(
            ObstacleScanner::new()
                .compute(&floor_only, None, w, &p)
                .valid_bins(),
            0
        );
        // Too few points: no range; a long-range scan fills the gap and is counted.
        let empty = ObstacleScanner::new().compute(&vec![0u16; w * h], None, w, &p);
        assert_eq!(empty.valid_bins(), 0);
        let merged = merge_scans(&empty, Some(&scan));
        assert_eq!((merged.valid_bins(), merged.hi_bins), (64, 64));
        assert_eq!(merge_scans(&scan, Some(&empty)), scan);
    }

    /// A disparity (px) that differs from row to row and column to column over 2..55 px: the
    /// matcher's false matches on a wall nearer than its shortest range.
    fn scattered_px(row: usize, column: usize) -> f64 {
        2.0 + ((row * 37 + column * 11) % 53) as f64
    }

    #[test]
    fn a_bin_of_scattered_depths_is_marked_scattered_and_a_near_object_beside_a_wall_is_kept() {
        // 64 columns, 40 rows, no height filter. Bins 0..32: the matcher's false matches on
        // a wall nearer than its shortest range, a different disparity on every row (2..55
        // px, scattered). Bins 32..64: a wall at 2 m with a nearer object (1 m) on a third
        // of the rows, as a pillar's edge gives.
        let (w, h) = (64usize, 40usize);
        let mut disp = vec![0u16; w * h];
        for v in 0..h {
            for x in 0..w {
                let d_px = if x < 32 {
                    scattered_px(v, x)
                } else if v % 3 == 0 {
                    19.2
                } else {
                    9.6
                };
                disp[v * w + x] = (d_px * 256.0).round() as u16;
            }
        }
        let p = params(3, RangeStatistic::Median);
        let scan = ObstacleScanner::new().compute(&disp, None, w, &p);
        for (i, &r) in scan.range_m.iter().enumerate() {
            if i < 32 {
                assert_eq!(r, SCAN_SCATTERED, "bin {i}: scattered depths read as {r} m");
            } else {
                // The 15th percentile lies on the near object, a tight cluster in front
                // of a surface that agrees with itself: the near object is reported.
                assert!(
                    (r - 1.0).abs() < 0.01,
                    "bin {i}: {r} m, want the object's 1 m"
                );
            }
        }
        // Scattered points in front of the wall on a quarter of the rows: the 15th
        // percentile lies among them and agrees with nothing. The bin reports nothing
        // rather than a phantom.
        for v in 0..h {
            for x in 32..w {
                disp[v * w + x] = if v % 4 == 0 {
                    2458 + 256 * v as u16
                } else {
                    2458
                };
            }
        }
        let scan = ObstacleScanner::new().compute(&disp, None, w, &p);
        assert_eq!(scan.range_m[40], SCAN_SCATTERED);
        assert_eq!(scan.valid_and_scattered(0..SCAN_BINS), (0, SCAN_BINS));
    }

    #[test]
    fn without_the_filter_a_bin_reports_its_percentile_whatever_the_spread() {
        // Scattered depths (the false matches on a wall too near to range): without the
        // filter the bin reads the 15th percentile of them, as open space.
        let (w, h) = (64usize, 40usize);
        let disp: Vec<u16> = (0..w * h)
            .map(|i| (scattered_px(i / w, i % w) * 256.0) as u16)
            .collect();
        let mut p = params(3, RangeStatistic::Median);
        p.scan_filter = ScanFilter::None;
        let scan = ObstacleScanner::new().compute(&disp, None, w, &p);
        assert_eq!(scan.valid_bins(), SCAN_BINS);
        p.scan_filter = ScanFilter::Agreement;
        let scan = ObstacleScanner::new().compute(&disp, None, w, &p);
        assert_eq!(scan.valid_and_scattered(0..SCAN_BINS), (0, SCAN_BINS));
    }

    #[test]
    fn a_wall_end_in_one_column_of_a_bin_is_reported_in_front_of_the_far_wall() {
        // 320 columns (5 a bin), 40 rows, no height filter: a far wall at 2 m, and a wall's
        // end at 1 m in the last column of bin 10 only. Pooled, the end is a fifth of the
        // bin's points; per column it is a surface of its own.
        let (w, h) = (320usize, 40usize);
        let mut disp = vec![(9.6 * 256.0) as u16; w * h];
        for v in 0..h {
            disp[v * w + 54] = (19.2 * 256.0) as u16;
        }
        let p = params(3, RangeStatistic::Median);
        let scan = ObstacleScanner::new().compute(&disp, None, w, &p);
        assert!(
            (scan.range_m[10] - 1.0).abs() < 0.01,
            "{}",
            scan.range_m[10]
        );
        assert!(
            (scan.range_m[11] - 2.0).abs() < 0.01,
            "{}",
            scan.range_m[11]
        );
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
            None,
            width,
            &params(3, RangeStatistic::Mean),
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
    fn robust_statistics_resist_an_outlier_the_mean_does_not() {
        let width = 10;
        let mut fused = vec![(19.2 * 256.0) as u16; width];
        fused[9] = 256; // 1 px disparity = 19.2 m: a gross mismatch
        let mut ranger = WindowRanger::new();
        let mut run = |statistic| {
            ranger.compute(&fused, None, width, &params(1, statistic), RangeSource::Lo)[0]
        };
        let mean = run(RangeStatistic::Mean);
        assert!(mean.range_m > 2.0, "{mean:?}");
        for statistic in [
            RangeStatistic::Median,
            RangeStatistic::TrimmedMean,
            RangeStatistic::Percentile,
        ] {
            let w = run(statistic);
            assert!((w.range_m - 1.0).abs() < 0.01, "{statistic:?}: {w:?}");
        }
    }

    #[test]
    fn near_percentile_finds_the_nearest_obstacle_and_confidence_follows_agreement() {
        let width = 100;
        // 70 pixels at 2 m, 30 at 0.5 m (an obstacle in front of a wall).
        let fused: Vec<u16> = (0..width)
            .map(|x| {
                if x < 30 {
                    (38.4 * 256.0) as u16
                } else {
                    (9.6 * 256.0) as u16
                }
            })
            .collect();
        let w = WindowRanger::new().compute(
            &fused,
            None,
            width,
            &params(1, RangeStatistic::Median),
            RangeSource::Lo,
        )[0];
        assert!((w.near_m - 0.5).abs() < 0.01, "{w:?}");
        assert!((w.range_m - 2.0).abs() < 0.01, "{w:?}");
        let uniform = vec![(9.6 * 256.0) as u16; width];
        let u = WindowRanger::new().compute(
            &uniform,
            None,
            width,
            &params(1, RangeStatistic::Median),
            RangeSource::Lo,
        )[0];
        assert!(u.confidence > w.confidence, "{u:?} vs {w:?}");
    }

    #[test]
    fn low_confidence_points_are_left_out_and_the_rest_weigh_by_confidence() {
        let width = 20;
        // 10 pixels at 1 m, 10 at 4 m; the far ones are mismatches the matcher doubted.
        let fused: Vec<u16> = (0..width)
            .map(|x| {
                if x < 10 {
                    (19.2 * 256.0) as u16
                } else {
                    (4.8 * 256.0) as u16
                }
            })
            .collect();
        let mut confidence = vec![250u8; width];
        confidence[10..].fill(5);
        let p = params(1, RangeStatistic::Mean);
        let plain = WindowRanger::new().compute(&fused, None, width, &p, RangeSource::Lo)[0];
        assert!((plain.range_m - 2.5).abs() < 0.01, "{plain:?}");
        let w =
            WindowRanger::new().compute(&fused, Some(&confidence), width, &p, RangeSource::Lo)[0];
        assert_eq!(w.valid_px, 10, "{w:?}");
        assert!((w.range_m - 1.0).abs() < 0.01, "{w:?}");
        // Kept points of unequal confidence: the mean leans to the confident ones.
        confidence[10..].fill(50);
        let w =
            WindowRanger::new().compute(&fused, Some(&confidence), width, &p, RangeSource::Lo)[0];
        assert_eq!(w.valid_px, 20);
        let expected = (250.0 * 1.0 + 50.0 * 4.0) / 300.0;
        assert!((w.mean_m as f64 - expected).abs() < 0.01, "{w:?}");
        // Less confident evidence, lower window confidence.
        let sure =
            WindowRanger::new().compute(&fused[..10], Some(&[250u8; 10]), 10, &p, RangeSource::Lo)
                [0];
        let unsure =
            WindowRanger::new().compute(&fused[..10], Some(&[60u8; 10]), 10, &p, RangeSource::Lo)
                [0];
        assert!(sure.confidence > unsure.confidence, "{sure:?} {unsure:?}");
    }

    #[test]
    fn floor_and_ceiling_points_are_left_out() {
        // A level camera 0.25 m up, f = 320, b = 0.06, 240 rows (cy = 119.5). The floor at
        // row v has d = (v - cy) * b / 0.25; a wall point in the middle row has height 0.25.
        let (width, height) = (4, 240);
        let mut fused = vec![0u16; width * height];
        let floor_row = 200usize;
        let d_floor = (floor_row as f64 - 119.5) * 0.06 / 0.25 * 320.0 / 320.0;
        // d in px: (v - cy) * f * b / (h * f)... with f = 320: d = (v - cy) * b / h * f / f.
        let d_floor_px = (floor_row as f64 - 119.5) * 0.06 * 320.0 / (0.25 * 320.0);
        assert!((d_floor - d_floor_px).abs() < 1e-9);
        fused[floor_row * width] = (d_floor_px * 256.0) as u16;
        fused[120 * width + 1] = (19.2 * 256.0) as u16; // wall at 1 m, mid height
        fused[2 * width + 2] = (1.0 * 256.0) as u16; // 19 m away near the top: far above 1.5 m
        let mut p = params(1, RangeStatistic::Mean);
        p.min_height_m = 0.05;
        p.max_height_m = 1.5;
        let w = WindowRanger::new().compute(&fused, None, width, &p, RangeSource::Lo)[0];
        assert_eq!(w.valid_px, 1, "{w:?}");
        assert!((w.range_m - 1.0).abs() < 0.01);
        p.min_height_m = 0.0;
        p.max_height_m = 0.0;
        let all = WindowRanger::new().compute(&fused, None, width, &p, RangeSource::Lo)[0];
        assert_eq!(all.valid_px, 3);
    }

    #[test]
    fn merge_takes_the_long_range_value_where_the_fast_path_is_thin() {
        let win = |range_m: f32, valid_px: u32, source: RangeSource| RangeWindow {
            range_m,
            valid_px,
            source: source as u32,
            ..Default::default()
        };
        let mut lo = [RangeWindow::default(); MAX_RANGE_WINDOWS];
        lo[0] = win(1.0, 100, RangeSource::Lo);
        lo[1] = win(1.9, 5, RangeSource::Lo);
        let mut hi = [RangeWindow::default(); MAX_RANGE_WINDOWS];
        hi[0] = win(3.0, 300, RangeSource::Hi);
        hi[1] = win(4.0, 200, RangeSource::Hi);
        hi[2] = win(5.0, 50, RangeSource::Hi);
        let m = merge_windows(&lo, Some(&hi), 30);
        assert_eq!(m[0].range_m, 1.0);
        assert_eq!(m[0].source, RangeSource::Lo as u32);
        assert_eq!(m[1].range_m, 4.0);
        assert_eq!(m[1].source, RangeSource::Hi as u32);
        assert_eq!(m[2].source, RangeSource::Hi as u32);
        assert_eq!(merge_windows(&lo, None, 30), lo);
    }
}
