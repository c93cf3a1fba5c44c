//! Raycast stereo renderer: an ideal rectified stereo pair of a [`GridMap`] with 2.4 m walls,
//! a flat floor and a flat ceiling, plus ground-truth disparity of the left image.
//!
//! Method: one exact grid ray per image column finds the wall (its depth is constant down the
//! column because cameras are level), and every pixel above/below the wall span is intersected
//! with the ceiling/floor plane analytically (depth is constant along a row). Textures are
//! world-anchored (see [`crate::texture`]), so the two eyes see the same surface pattern.
//!
//! Camera model: pinhole, pixel `(px, py)` (0-based, `py` down) looks along
//! `forward + right * (px - cx_px) / focal_px - up * (py - cy_px) / focal_px`; the principal point
//! defaults to the image centre `((width-1)/2, (height-1)/2)`. A world point at depth `Z` (along
//! the optical axis) seen at column `x` in the left image is seen at column `x - d` in the right
//! image, with `d = focal_px * baseline_m / Z`.

use crate::map::{Face, GridMap, Pose, Vec2};
use crate::texture::{
    NoiseTable, PlaneRow, QuadCache, SceneDecor, ShadeState, Textures, WALL_HEIGHT_M, WallColumn,
};

/// Geometry of the simulated stereo camera (an ideal rectified pair, cameras parallel and level).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoRig {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Focal length in pixels (same for x and y).
    pub focal_px: f64,
    /// Principal point column (0-based pixel index coordinates).
    pub cx_px: f64,
    /// Principal point row (0-based pixel index coordinates).
    pub cy_px: f64,
    /// Distance between the two optical centres, metres.
    pub baseline_m: f64,
    /// Height of the optical centres above the floor, metres.
    pub camera_height_m: f64,
    /// Distance of the rig centre ahead of the robot centre, metres.
    pub camera_forward_m: f64,
}

/// Default stereo baseline (Minoru), metres.
pub const DEFAULT_BASELINE_M: f64 = 0.060;
/// Default camera height above the floor, metres.
pub const DEFAULT_CAMERA_HEIGHT_M: f64 = 0.25;
/// Default distance of the cameras ahead of the robot centre, metres.
pub const DEFAULT_CAMERA_FORWARD_M: f64 = 0.20;

impl StereoRig {
    /// A rig of the given size and focal length with default baseline, height and mounting, and
    /// the principal point at the image centre.
    pub fn new(width: usize, height: usize, focal_px: f64) -> Self {
        StereoRig {
            width,
            height,
            focal_px,
            cx_px: (width as f64 - 1.0) / 2.0,
            cy_px: (height as f64 - 1.0) / 2.0,
            baseline_m: DEFAULT_BASELINE_M,
            camera_height_m: DEFAULT_CAMERA_HEIGHT_M,
            camera_forward_m: DEFAULT_CAMERA_FORWARD_M,
        }
    }

    /// 640x480 with f = 640 px.
    pub fn vga() -> Self {
        Self::new(640, 480, 640.0)
    }

    /// 320x240 with f = 320 px.
    pub fn qvga() -> Self {
        Self::new(320, 240, 320.0)
    }

    /// Number of pixels of one image.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// Disparity in pixels of a point at `depth_m` along the optical axis.
    pub fn disparity_px(&self, depth_m: f64) -> f64 {
        self.focal_px * self.baseline_m / depth_m
    }

    /// World position of an eye's optical centre for the robot (rig) pose.
    pub fn eye_position(&self, rig_pose: &Pose, eye: Eye) -> Vec2 {
        let side = match eye {
            Eye::Left => 0.5 * self.baseline_m,
            Eye::Right => -0.5 * self.baseline_m,
        };
        rig_pose.offset(self.camera_forward_m, side).position()
    }
}

/// One of the two cameras.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Eye {
    /// The left camera, `baseline/2` to the left of the rig centre.
    Left,
    /// The right camera, `baseline/2` to the right of the rig centre.
    Right,
}

/// Errors of rendering.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    /// A buffer has the wrong length for the rig.
    #[error("{what} buffer has {got} elements, expected {expected}")]
    BufferSize {
        /// Which buffer.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// The eye's optical centre is inside a wall or outside the map.
    #[error("{eye:?} eye at x={x_m:.3} m, y={y_m:.3} m is inside a wall or outside the map")]
    EyeInsideWall {
        /// Which eye.
        eye: Eye,
        /// Eye x.
        x_m: f64,
        /// Eye y.
        y_m: f64,
    },
    /// The rig has an unusable size or focal length.
    #[error("unusable rig: {width}x{height} px, focal {focal_px} px")]
    BadRig {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Focal length.
        focal_px: f64,
    },
}

/// A renderer bound to one map and rig (it precomputes the wall decorations of the map).
#[derive(Debug, Clone)]
pub struct Renderer {
    rig: StereoRig,
    map: GridMap,
    decor: SceneDecor,
}

/// Column data of one eye's image.
struct ColumnData<'a> {
    tex: Vec<WallColumn<'a>>,
    /// Depth along the optical axis of the wall in each column.
    depth_m: Vec<f32>,
    /// Quantised ground-truth disparity of the wall in each column.
    gt: Vec<u16>,
    /// Wall covers rows `py` with `top < py <= bottom`.
    top: Vec<f32>,
    bottom: Vec<f32>,
}

impl Renderer {
    /// Prepares a renderer for `map` (cloned) and `rig`.
    pub fn new(map: &GridMap, rig: StereoRig) -> Self {
        Renderer {
            rig,
            decor: SceneDecor::new(map),
            map: map.clone(),
        }
    }

    /// The rig.
    pub fn rig(&self) -> &StereoRig {
        &self.rig
    }

    /// The map.
    pub fn map(&self) -> &GridMap {
        &self.map
    }

    /// Renders the left eye from `pose_left` and the right eye from `pose_right` (robot poses;
    /// they differ when the right camera is not synchronised) into grey row-major images, and
    /// optionally the left image's ground-truth disparity as `round(d * 256)` (0 = unknown,
    /// saturating at 65535).
    pub fn render_pair(
        &self,
        pose_left: &Pose,
        pose_right: &Pose,
        left: &mut [u8],
        right: &mut [u8],
        gt_disparity_q8: Option<&mut [u16]>,
    ) -> Result<(), RenderError> {
        self.render_eye(Eye::Left, pose_left, left, gt_disparity_q8)?;
        self.render_eye(Eye::Right, pose_right, right, None)
    }

    /// Renders one eye from robot pose `rig_pose`; `gt_disparity_q8` receives that eye's
    /// disparity `round(focal * baseline / Z * 256)` per pixel.
    pub fn render_eye(
        &self,
        eye: Eye,
        rig_pose: &Pose,
        image: &mut [u8],
        gt_disparity_q8: Option<&mut [u16]>,
    ) -> Result<(), RenderError> {
        let rig = &self.rig;
        let (w, h) = (rig.width, rig.height);
        if w == 0 || h == 0 || !(rig.focal_px.is_finite() && rig.focal_px > 0.0) {
            return Err(RenderError::BadRig {
                width: w,
                height: h,
                focal_px: rig.focal_px,
            });
        }
        let n = w * h;
        if image.len() != n {
            return Err(RenderError::BufferSize {
                what: "image",
                expected: n,
                got: image.len(),
            });
        }
        let mut gt = gt_disparity_q8;
        if let Some(g) = gt.as_deref()
            && g.len() != n
        {
            return Err(RenderError::BufferSize {
                what: "ground-truth disparity",
                expected: n,
                got: g.len(),
            });
        }
        let eye_pos = rig.eye_position(rig_pose, eye);
        let inside_err = || RenderError::EyeInsideWall {
            eye,
            x_m: eye_pos.x,
            y_m: eye_pos.y,
        };
        if self.map.is_wall_at(eye_pos.x, eye_pos.y) {
            return Err(inside_err());
        }
        let cols = self
            .columns(Textures::get(), rig_pose, eye_pos)
            .ok_or_else(inside_err)?;
        let noise = NoiseTable::get();
        let tex = Textures::get();
        let seed = self.decor.seed;
        let fwd = rig_pose.forward();
        let right_v = rig_pose.left() * -1.0;
        let f = rig.focal_px;
        let cam_h = rig.camera_height_m;
        let fb = (f * rig.baseline_m) as f32;
        let inv_f = (1.0 / f) as f32;
        let cy = rig.cy_px as f32;
        for py in 0..h {
            let dy = py as f64 - rig.cy_px;
            let row_img = &mut image[py * w..(py + 1) * w];
            let row_gt = gt.as_deref_mut().map(|g| &mut g[py * w..(py + 1) * w]);
            // Plane (floor below the horizon, ceiling above) for this row.
            let plane_h = if dy > 0.0 {
                cam_h
            } else {
                WALL_HEIGHT_M - cam_h
            };
            let plane_z = if dy != 0.0 {
                plane_h * f / dy.abs()
            } else {
                f64::INFINITY
            };
            let a0 = (0.0 - rig.cx_px) / f;
            // World point of pixel 0 on the plane, and its step per pixel.
            let x0 = (eye_pos.x + plane_z * (fwd.x + right_v.x * a0)) as f32;
            let y0 = (eye_pos.y + plane_z * (fwd.y + right_v.y * a0)) as f32;
            let step_x = (plane_z * right_v.x / f) as f32;
            let step_y = (plane_z * right_v.y / f) as f32;
            let fp_lat = plane_z / f;
            let fp_dep = plane_z * plane_z / (plane_h * f);
            let fp_x = (right_v.x.abs() * fp_lat + fwd.x.abs() * fp_dep) as f32;
            let fp_y = (right_v.y.abs() * fp_lat + fwd.y.abs() * fp_dep) as f32;
            let plane_gt = quantise_disparity(fb / plane_z as f32);
            let plane_row = PlaneRow::new(tex, dy < 0.0, fp_x, fp_y, seed);
            let pyf = py as f32;
            let (tops, bottoms) = (&cols.top[..w], &cols.bottom[..w]);
            if let Some(g) = row_gt {
                let plane_gt = if plane_z.is_finite() { plane_gt } else { 0 };
                for (((v, &top), &bottom), &wall_gt) in
                    g.iter_mut().zip(tops).zip(bottoms).zip(&cols.gt)
                {
                    *v = if pyf > top && pyf <= bottom {
                        wall_gt
                    } else {
                        plane_gt
                    };
                }
            }
            if !plane_z.is_finite() {
                continue; // the horizon row of a pixel grid with an integer principal point
            }
            let mut x = x0;
            let mut y = y0;
            let mut cache = QuadCache::default();
            for ((pix, &top), &bottom) in row_img.iter_mut().zip(tops).zip(bottoms) {
                // Wall pixels are written by the column pass below.
                if !(pyf > top && pyf <= bottom) {
                    *pix = to_grey(plane_row.shade(&mut cache, x, y));
                }
                x += step_x;
                y += step_y;
            }
        }
        // Wall pass, column by column: texture reads stay local (the wall textures are stored
        // column-major) and the column shader caches texel rows between pixels.
        for px in 0..w {
            let zc = cols.depth_m[px];
            let first = (cols.top[px].floor() + 1.0).max(0.0) as usize;
            let last = (cols.bottom[px].floor()).min(h as f32 - 1.0);
            if last < 0.0 {
                continue;
            }
            let last = last as usize;
            let col_tex = &cols.tex[px];
            let mut state = ShadeState::default();
            let dz = zc * inv_f;
            let mut z = cam_h as f32 - (first as f32 - cy) * dz;
            for pix in image[first * w + px..=last * w + px].iter_mut().step_by(w) {
                *pix = to_grey(col_tex.shade(&mut state, noise, z));
                z -= dz;
            }
        }
        Ok(())
    }

    /// Casts one ray per column and prepares the wall data of every column.
    fn columns<'a>(
        &'a self,
        tex: &'a Textures,
        rig_pose: &Pose,
        eye_pos: Vec2,
    ) -> Option<ColumnData<'a>> {
        let rig = &self.rig;
        let w = rig.width;
        let f = rig.focal_px;
        let cam_h = rig.camera_height_m;
        let fwd = rig_pose.forward();
        let right_v = rig_pose.left() * -1.0;
        let mut cols = ColumnData {
            tex: Vec::with_capacity(w),
            depth_m: Vec::with_capacity(w),
            gt: Vec::with_capacity(w),
            top: Vec::with_capacity(w),
            bottom: Vec::with_capacity(w),
        };
        for px in 0..w {
            let a = (px as f64 - rig.cx_px) / f;
            let dir = fwd + right_v * a;
            let hit = self.map.cast_ray(eye_pos, dir)?;
            // `dir` has unit forward component, so the ray parameter is the optical depth.
            let depth = hit.distance_m / dir.length();
            let (tau, s) = match hit.face {
                Face::North | Face::South => (Vec2::new(1.0, 0.0), hit.point.x),
                Face::East | Face::West => (Vec2::new(0.0, 1.0), hit.point.y),
            };
            let nd = hit.normal.dot(dir);
            let ds_da = if nd.abs() > 1e-9 {
                depth * (tau.dot(right_v) - tau.dot(dir) * hit.normal.dot(right_v) / nd)
            } else {
                1e3
            };
            let fp_s = (ds_da.abs() / f).min(100.0) as f32;
            let fp_z = (depth / f) as f32;
            let run = self.decor.run_of(hit.cell_col, hit.cell_row, hit.face);
            cols.tex.push(WallColumn::new(
                tex,
                s as f32,
                fp_s,
                fp_z,
                run,
                self.map.wall_contrast() as f32,
            ));
            cols.depth_m.push(depth as f32);
            cols.gt.push(quantise_disparity(
                (rig.focal_px * rig.baseline_m / depth) as f32,
            ));
            cols.top
                .push((rig.cy_px - (WALL_HEIGHT_M - cam_h) * f / depth) as f32);
            cols.bottom.push((rig.cy_px + cam_h * f / depth) as f32);
        }
        Some(cols)
    }
}

/// Rounds a grey level to u8 (the float-to-int cast saturates at 0 and 255).
#[inline(always)]
fn to_grey(v: f32) -> u8 {
    (v + 0.5) as u8
}

/// `round(d * 256)` saturated to u16 (0 stays "unknown" only for d = 0).
#[inline(always)]
fn quantise_disparity(d_px: f32) -> u16 {
    (d_px * 256.0 + 0.5).clamp(0.0, 65535.0) as u16
}

/// Renders a stereo pair of `map` with `rig` (convenience wrapper that builds a [`Renderer`]
/// each call; keep a [`Renderer`] for repeated rendering). See [`Renderer::render_pair`].
pub fn render_pair(
    map: &GridMap,
    rig: &StereoRig,
    pose_left: &Pose,
    pose_right: &Pose,
    left: &mut [u8],
    right: &mut [u8],
    gt_disparity_q8: Option<&mut [u16]>,
) -> Result<(), RenderError> {
    Renderer::new(map, *rig).render_pair(pose_left, pose_right, left, right, gt_disparity_q8)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 7 m x 5 m room (cells of 0.5 m) with a pillar, the robot at the west side facing east.
    const ROOM: &str = "@cell_m 0.5
################
#..............#
#..............#
#........##....#
#........##....#
#.>............#
#..............#
#..............#
#..............#
#..............#
################";

    fn room() -> GridMap {
        GridMap::parse(ROOM, "room").unwrap()
    }

    fn render(rig: StereoRig, pose: &Pose) -> (Vec<u8>, Vec<u8>, Vec<u16>) {
        let n = rig.pixels();
        let (mut l, mut r, mut g) = (vec![0u8; n], vec![0u8; n], vec![0u16; n]);
        Renderer::new(&room(), rig)
            .render_pair(pose, pose, &mut l, &mut r, Some(&mut g))
            .unwrap();
        (l, r, g)
    }

    #[test]
    fn ground_truth_of_wall_ahead_is_fb_over_z() {
        let map = room();
        let rig = StereoRig::vga();
        // Facing east from (1.25, 2.75): the east wall face is at x = 7.5 (the pillar is north).
        let pose = Pose::from_deg(1.25, 2.25, 0.0);
        let (_, _, gt) = render(rig, &pose);
        let z = 7.5 - (pose.x_m + rig.camera_forward_m);
        let expect = (rig.focal_px * rig.baseline_m / z * 256.0).round() as u16;
        let (w, h) = (rig.width, rig.height);
        // Centre columns, rows around the horizon: all on the front wall.
        for y in (h / 2 - 20)..(h / 2 + 20) {
            for x in [w / 2 - 1, w / 2, w / 2 + 1, w / 2 + 50] {
                assert_eq!(gt[y * w + x], expect, "pixel ({x},{y})");
            }
        }
        // Bottom row: floor at depth h_cam * f / (y - cy).
        let y = h - 1;
        let zf = rig.camera_height_m * rig.focal_px / (y as f64 - rig.cy_px);
        let expect_floor = (rig.focal_px * rig.baseline_m / zf * 256.0).round() as u16;
        assert_eq!(gt[y * w + w / 2], expect_floor);
        // An enclosed map gives every pixel a depth.
        assert!(gt.iter().all(|&d| d > 0));
        // Cross-check one wall depth against the map's ray caster.
        let eye = rig.eye_position(&pose, Eye::Left);
        let hit = map.cast_ray(eye, pose.forward()).unwrap();
        assert!((hit.distance_m - z).abs() < 1e-12);
    }

    /// Bilinear sample of row `y` at fractional column `x`.
    fn sample(img: &[u8], w: usize, x: f64, y: usize) -> Option<f64> {
        if x < 0.0 || x > (w - 1) as f64 {
            return None;
        }
        let x0 = x.floor() as usize;
        let x1 = (x0 + 1).min(w - 1);
        let f = x - x0 as f64;
        Some(f64::from(img[y * w + x0]) * (1.0 - f) + f64::from(img[y * w + x1]) * f)
    }

    fn photo_consistency(rig: StereoRig, pose: &Pose) -> (f64, f64, usize) {
        let (l, r, g) = render(rig, pose);
        let renderer = Renderer::new(&room(), rig);
        let mut gr = vec![0u16; rig.pixels()];
        let mut scratch = vec![0u8; rig.pixels()];
        renderer
            .render_eye(Eye::Right, pose, &mut scratch, Some(&mut gr))
            .unwrap();
        let w = rig.width;
        let mut diffs = Vec::new();
        for y in 0..rig.height {
            for x in 0..w {
                let d = f64::from(g[y * w + x]) / 256.0;
                let xr = x as f64 - d;
                // Skip pixels occluded in the right image (its depth there differs).
                let xr_i = xr.round();
                if xr_i < 0.0 || xr_i >= w as f64 {
                    continue;
                }
                let dr = f64::from(gr[y * w + xr_i as usize]) / 256.0;
                if (dr - d).abs() > 0.05 * d + 0.5 {
                    continue;
                }
                if let Some(v) = sample(&r, w, xr, y) {
                    diffs.push((f64::from(l[y * w + x]) - v).abs());
                }
            }
        }
        diffs.sort_by(f64::total_cmp);
        let n = diffs.len();
        (diffs[n / 2], diffs[n * 9 / 10], n)
    }

    #[test]
    fn left_pixel_matches_right_pixel_shifted_by_disparity() {
        for (rig, pose) in [
            (StereoRig::vga(), Pose::from_deg(1.25, 2.75, 0.0)),
            (StereoRig::vga(), Pose::from_deg(3.0, 1.5, 35.0)),
            (StereoRig::qvga(), Pose::from_deg(5.5, 3.0, 200.0)),
        ] {
            let (median, p90, n) = photo_consistency(rig, &pose);
            assert!(n > rig.pixels() * 8 / 10, "most pixels are checked: {n}");
            assert!(median <= 2.0, "median |L - R| {median} at {pose:?}");
            assert!(p90 <= 8.0, "90th percentile |L - R| {p90} at {pose:?}");
        }
    }

    /// Fraction of 8x8 blocks whose grey-level standard deviation exceeds `min_std`.
    fn textured_fraction(img: &[u8], w: usize, h: usize, min_std: f64) -> f64 {
        let (mut ok, mut all) = (0usize, 0usize);
        for by in 0..h / 8 {
            for bx in 0..w / 8 {
                let vals: Vec<f64> = (0..64)
                    .map(|i| f64::from(img[(by * 8 + i / 8) * w + bx * 8 + i % 8]))
                    .collect();
                let mean = vals.iter().sum::<f64>() / 64.0;
                let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 64.0;
                all += 1;
                if var.sqrt() > min_std {
                    ok += 1;
                }
            }
        }
        ok as f64 / all as f64
    }

    #[test]
    fn texture_has_no_flat_regions() {
        for rig in [StereoRig::vga(), StereoRig::qvga()] {
            for pose in [
                Pose::from_deg(1.25, 2.75, 0.0),
                Pose::from_deg(1.0, 1.0, 45.0),
                Pose::from_deg(6.0, 4.0, 180.0),
            ] {
                let (l, r, _) = render(rig, &pose);
                for img in [&l, &r] {
                    let f = textured_fraction(img, rig.width, rig.height, 2.0);
                    assert!(
                        f > 0.95,
                        "{f} of 8x8 blocks textured at {pose:?} {}",
                        rig.width
                    );
                }
                // No saturated or constant images either.
                let min = l.iter().min().copied().unwrap_or(0);
                let max = l.iter().max().copied().unwrap_or(0);
                assert!(max - min > 100, "contrast {min}..{max}");
            }
        }
    }

    /// Grey levels of the front wall around the horizon from `pose` (all one wall run).
    fn front_wall_block(map: &GridMap, pose: &Pose) -> Vec<f64> {
        let rig = StereoRig::qvga();
        let n = rig.pixels();
        let (mut l, mut r) = (vec![0u8; n], vec![0u8; n]);
        Renderer::new(map, rig)
            .render_pair(pose, pose, &mut l, &mut r, None)
            .unwrap();
        let (w, h) = (rig.width, rig.height);
        // Rows above the wall's foot 6 m away (12 rows below the horizon).
        (h / 2 - 20..h / 2 + 8)
            .flat_map(|y| (w / 2 - 40..w / 2 + 40).map(move |x| y * w + x))
            .map(|i| f64::from(l[i]))
            .collect()
    }

    fn spread(v: &[f64]) -> f64 {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
    }

    #[test]
    fn wall_contrast_scales_the_wall_texture() {
        let pose = Pose::from_deg(1.25, 2.25, 0.0);
        let with = |c: Option<f64>| {
            let text = match c {
                Some(c) => format!("@wall_contrast {c}\n{ROOM}"),
                None => ROOM.to_string(),
            };
            front_wall_block(&GridMap::parse(&text, "room").unwrap(), &pose)
        };
        let full = with(None);
        assert_eq!(full, with(Some(1.0)), "1 is today's texture");
        let s_full = spread(&full);
        assert!(s_full > 5.0, "{s_full}");
        let plain = with(Some(0.0));
        assert!(
            plain.iter().all(|&v| v == plain[0]),
            "plain paint is one grey"
        );
        let half = spread(&with(Some(0.5)));
        assert!((half / s_full - 0.5).abs() < 0.05, "{half} vs {s_full}");
        // The override does the same as the directive.
        let mut m = room();
        m.set_wall_contrast(0.0);
        assert_eq!(front_wall_block(&m, &pose), plain);
        // Different walls get different flat paint; floor and ceiling keep their texture.
        let rig = StereoRig::qvga();
        let n = rig.pixels();
        let (mut l, mut r) = (vec![0u8; n], vec![0u8; n]);
        let corner = Pose::from_deg(6.0, 1.5, -45.0);
        Renderer::new(&m, rig)
            .render_pair(&corner, &corner, &mut l, &mut r, None)
            .unwrap();
        let (w, h) = (rig.width, rig.height);
        let row: Vec<u8> = l[(h / 2) * w..(h / 2 + 1) * w].to_vec();
        let mut greys: Vec<u8> = row.clone();
        greys.dedup();
        let (lo, hi) = (greys.iter().min(), greys.iter().max());
        assert!(
            greys.len() == 2 && hi.zip(lo).is_some_and(|(h, l)| h - l >= 8),
            "two flat walls meet at the corner: {greys:?}"
        );
        let floor_row = &l[(h - 1) * w..h * w];
        assert!(spread(&floor_row.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()) > 2.0);
    }

    #[test]
    fn renders_are_deterministic_and_eyes_differ() {
        let pose = Pose::from_deg(2.0, 2.0, 10.0);
        let a = render(StereoRig::qvga(), &pose);
        let b = render(StereoRig::qvga(), &pose);
        assert_eq!(a, b);
        assert_ne!(a.0, a.1, "the eyes are 6 cm apart");
    }

    #[test]
    fn native_qvga_matches_downscaled_vga() {
        let pose = Pose::from_deg(1.25, 2.75, 0.0);
        let (l_vga, _, _) = render(StereoRig::vga(), &pose);
        let (l_qvga, _, _) = render(StereoRig::qvga(), &pose);
        let mut down = vec![0u8; 320 * 240];
        // The capture stage's downscale: what the pipeline does with a VGA pair.
        hvs_capture::downscale_2x(&l_vga, 640, 480, &mut down).unwrap();
        let mad = down
            .iter()
            .zip(&l_qvga)
            .map(|(a, b)| (f64::from(*a) - f64::from(*b)).abs())
            .sum::<f64>()
            / down.len() as f64;
        assert!(mad < 6.0, "mean |downscaled VGA - native QVGA| = {mad}");
    }

    #[test]
    fn bad_inputs_are_errors() {
        let map = room();
        let rig = StereoRig::qvga();
        let r = Renderer::new(&map, rig);
        let n = rig.pixels();
        let (mut l, mut rr) = (vec![0u8; n], vec![0u8; n]);
        let mut short = vec![0u16; n - 1];
        let p = map.start_pose();
        assert!(matches!(
            r.render_pair(&p, &p, &mut l, &mut rr, Some(&mut short)),
            Err(RenderError::BufferSize { .. })
        ));
        assert!(matches!(
            r.render_pair(&p, &p, &mut l[..n - 1], &mut rr, None),
            Err(RenderError::BufferSize { .. })
        ));
        let inside = Pose::from_deg(0.1, 0.1, 0.0);
        assert!(matches!(
            r.render_pair(&inside, &inside, &mut l, &mut rr, None),
            Err(RenderError::EyeInsideWall { .. })
        ));
    }
}
