//! Ogale & Aloimonos "shape and stereo correspondence", the matcher the reference robot used.
//!
//! Two readings of the method are implemented (`docs/ogale.md` lists every choice made):
//!
//! - [`OgaleVariant::Components`] (the default; the IJCV 2005 / thesis description): for every
//!   hypothesis a binary match map `M(p) = [BT(p) <= match_threshold]`; matching neighbours are
//!   linked horizontally always and vertically only where no horizontal edge of the left image
//!   separates them; the goodness of a pixel is the size of its connected component, found with
//!   a run-length union-find (runs of matches in a row are the nodes, not pixels).
//! - [`OgaleVariant::Diffusion`] (the released OpenVis3D code): a soft match
//!   `exp(-alpha/255 * BT)` diffused along rows and columns; goodness = row support x column
//!   support, a cross-shaped stand-in for the component size.
//!
//! Both share the rest. Horizontal slant is handled with stretch factors: for every factor `m`
//! the right image is resampled at `m * x'` (linear interpolation) and matched with integer
//! shifts `s`, so hypothesis `(m, s)` pairs left `x` with right `m * (x - s)`: the slanted
//! plane `d(x) = (1 - m) * x + m * s`. Every left pixel keeps the hypothesis with the largest
//! goodness under a greedy two-sided uniqueness (it takes a hypothesis only if its goodness
//! beats both its own best and what its right partner has already granted), then an ambiguity
//! test (`uniqueness_pct`), an optional subpixel fit, OpenVis3D's 3x3 median, the left-right
//! check that marks occlusions, and the speckle filter.

use hvs_runtime::config::StereoConfig;
use hvs_shared::messages::StereoAlgorithm;

use crate::equalize::equalize_right;
use crate::post::{lr_check, median3x3, parabola_offset, speckle_filter};
use crate::{
    ImageView, MatchStats, StereoError, StereoMatcher, bad_parameter, check_fits, check_pair,
    check_range, check_uniqueness,
};

/// Which reading of Ogale & Aloimonos to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OgaleVariant {
    /// Binary matches, connected components (run-length union-find), largest component wins.
    #[default]
    Components,
    /// OpenVis3D: soft matches diffused along rows and columns, goodness = row x column support.
    Diffusion,
}

/// The variant [`OgaleMatcher::from_config`] builds (the config has no field for it).
pub const DEFAULT_VARIANT: OgaleVariant = OgaleVariant::Components;

/// The pixel dissimilarity behind a match. The intensity forms are all symmetric Birchfield-
/// Tomasi: `BT = (d1 + d2) / 2` with `d1 = max(0, Rmin - L, L - Rmax)` and
/// `d2 = max(0, Lmin - R, R - Lmax)`, where `[Imin, Imax]` is the half-interval around a pixel
/// (`Imin = (I + min over a neighbourhood) / 2`); they differ in the neighbourhood.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MatchFunction {
    /// Plain absolute difference `|L - R|` (no neighbourhood), the thesis's wording.
    AbsDiff,
    /// Classic Birchfield-Tomasi: the two horizontal neighbours (1x3).
    #[default]
    Bt1x3,
    /// OpenVis3D's form: the 3x3 neighbourhood (also tolerates some vertical misalignment).
    Bt3x3,
    /// The contrast-invariant substitute of the notes (section 1.5): Hamming distance of 5x5
    /// census strings (24 bits), blind to any gain and offset between the cameras. With it,
    /// `match_threshold` counts differing bits and the diffusion's soft match is
    /// `exp(-CENSUS_BETA * hamming)`.
    Census,
}

impl MatchFunction {
    /// The match function [`OgaleMatcher::from_config`] uses for a variant: classic BT for
    /// the components (it gave steadier maps than the 3x3 form once the vertical search is on),
    /// OpenVis3D's 3x3 form for the diffusion (as released).
    pub fn default_for(variant: OgaleVariant) -> Self {
        match variant {
            OgaleVariant::Components => MatchFunction::Bt1x3,
            OgaleVariant::Diffusion => MatchFunction::Bt3x3,
        }
    }
}

/// How the right image is brought to the left's radiometry before matching.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Equalization {
    /// Images used as they are.
    Off,
    /// The reference step (`equalize::equalize_right`): right scaled by `sum(L) / sum(R)`;
    /// corrects a global gain only.
    #[default]
    SumRatio,
    /// Right mapped to the left's mean and standard deviation: undoes a global gain *and*
    /// offset (the notes' section 1.7 suggestion).
    MeanStd,
}

/// What `StereoConfig::equalize = true` selects in [`OgaleParams::from_config`].
pub const DEFAULT_EQUALIZATION: Equalization = Equalization::SumRatio;

/// Vertical search of the components variant in [`OgaleParams::from_config`]: a pixel's cost is
/// the smallest over right rows `y - v ..= y + v`, for webcams that are not perfectly rectified.
/// (The diffusion variant defaults to 0, as released: with the 3x3 BT the search made it lose
/// slanted surfaces.)
pub const DEFAULT_VERTICAL_SEARCH_PX: u32 = 1;

/// Largest vertical search accepted.
pub const MAX_VERTICAL_SEARCH_PX: u32 = 2;

/// OpenVis3D's `alpha` of the diffusion variant: soft match `exp(-alpha/255 * BT)` ("smaller
/// alpha, smoother"). Its default, 20, is kept.
pub const DIFFUSION_ALPHA: f32 = 20.0;

/// Soft match of the diffusion variant with [`MatchFunction::Census`]: `exp(-beta * hamming)`.
pub const CENSUS_BETA: f32 = 0.5;

/// Diffusion goodness below which a hypothesis is not offered to the winner-take-all: a pixel
/// whose every hypothesis is weaker stays invalid instead of taking noise. (A lone perfect match
/// scores 1; a lone census match at Hamming distance 4 scores 0.14^2 = 0.02.)
pub const DIFFUSION_MIN_GOODNESS: f32 = 0.01;

/// Apply OpenVis3D's 3x3 median to the left and right disparity maps before the left-right
/// check (invalid pixels take part as 0). It removes the isolated pixels that missed their true
/// hypothesis and took whatever component held them.
pub const MEDIAN_BEFORE_LR: bool = true;

/// Smallest stretch factor accepted.
pub const MIN_STRETCH: f32 = 0.5;
/// Largest stretch factor accepted.
pub const MAX_STRETCH: f32 = 2.0;

/// Census window of [`MatchFunction::Census`] (5x5: 24 comparisons).
const CENSUS_WIN: usize = 5;

/// Half-width of the window of the subpixel fit (5x3: 2 columns and 1 row either side).
const SUBPIXEL_RX: usize = 2;
/// Half-height of the window of the subpixel fit.
const SUBPIXEL_RY: usize = 1;

/// Largest disparity the 1/256-px `u16` output can hold.
const MAX_DISP_PX: u32 = 255;

/// Widest image accepted (runs store columns as `u16`).
const MAX_WIDTH_PX: usize = u16::MAX as usize;

/// Ogale & Aloimonos parameters: the crate-level [`StereoConfig`] flattened, plus the choices
/// the config has no field for.
#[derive(Debug, Clone, PartialEq)]
pub struct OgaleParams {
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px (inclusive).
    pub max_disp: u32,
    /// Radiometric equalisation of the right image before matching.
    pub equalization: Equalization,
    /// Left-right consistency check; pixels failing it are marked occluded (invalid).
    pub lr_check: bool,
    /// Allowed left-right disagreement, px.
    pub lr_max_diff_px: u32,
    /// Refine the winning disparity with a parabola through 5x3 SAD costs at the winning
    /// hypothesis moved by -1, 0, +1 (resampled) right pixels.
    pub subpixel: bool,
    /// Ambiguity test: a pixel stays valid only if its best goodness beats every rival
    /// hypothesis (more than `max(stretch) + 0.5` px away, i.e. not a neighbouring shift) by
    /// this many percent (0 disables).
    pub uniqueness_pct: u32,
    /// Speckle filter: regions of at most this many pixels are removed (0 disables).
    pub speckle_window_px: u32,
    /// Speckle filter: neighbours within this many px are one region.
    pub speckle_range_px: u32,
    /// Components variant: a pixel matches when its dissimilarity is at most this (grey levels;
    /// differing bits for [`MatchFunction::Census`]).
    pub match_threshold: u32,
    /// Horizontal stretch factors (1.0 = fronto-parallel); tried in order of `|1 - m|`.
    pub stretch: Vec<f32>,
    /// Cut vertical links where a horizontal edge of the left image separates two pixels.
    pub cut_horizontal_edges: bool,
    /// Vertical grey difference that counts as a horizontal edge.
    pub edge_threshold: u32,
    /// Which reading of the method to run.
    pub variant: OgaleVariant,
    /// The pixel dissimilarity.
    pub match_fn: MatchFunction,
    /// Tolerated vertical misalignment, px: a pixel's cost is the smallest over right rows
    /// `y - v ..= y + v` (0 = rectified pair, same row only).
    pub vertical_search_px: u32,
}

impl Default for OgaleParams {
    fn default() -> Self {
        Self::from_config(&StereoConfig::default())
    }
}

impl OgaleParams {
    /// Takes the parameters from a config section, with [`DEFAULT_VARIANT`] and its defaults
    /// (see [`OgaleParams::with_variant`]), and [`DEFAULT_EQUALIZATION`] when `equalize` is set.
    pub fn from_config(config: &StereoConfig) -> Self {
        Self {
            min_disp: config.min_disp,
            max_disp: config.max_disp,
            equalization: if config.equalize {
                DEFAULT_EQUALIZATION
            } else {
                Equalization::Off
            },
            lr_check: config.lr_check,
            lr_max_diff_px: config.lr_max_diff_px,
            subpixel: config.subpixel,
            uniqueness_pct: config.uniqueness_pct,
            speckle_window_px: config.speckle_window_px,
            speckle_range_px: config.speckle_range_px,
            match_threshold: config.ogale.match_threshold,
            stretch: config.ogale.stretch.clone(),
            cut_horizontal_edges: config.ogale.cut_horizontal_edges,
            edge_threshold: config.ogale.edge_threshold,
            variant: DEFAULT_VARIANT,
            match_fn: MatchFunction::Bt1x3,
            vertical_search_px: 0,
        }
        .with_variant(DEFAULT_VARIANT)
    }

    /// The same parameters with another variant and that variant's defaults: match function
    /// [`MatchFunction::default_for`] and vertical search [`DEFAULT_VERTICAL_SEARCH_PX`] for the
    /// components, none for the diffusion.
    pub fn with_variant(self, variant: OgaleVariant) -> Self {
        Self {
            variant,
            match_fn: MatchFunction::default_for(variant),
            vertical_search_px: match variant {
                OgaleVariant::Components => DEFAULT_VERTICAL_SEARCH_PX,
                OgaleVariant::Diffusion => 0,
            },
            ..self
        }
    }

    /// Checks the parameters on their own (image size is checked per call).
    pub fn validate(&self) -> Result<(), StereoError> {
        check_range(self.min_disp, self.max_disp)?;
        if self.max_disp > MAX_DISP_PX {
            return bad_parameter(
                "max_disp",
                format!(
                    "= {} is above {MAX_DISP_PX} px, the most a 1/256-px map holds",
                    self.max_disp
                ),
            );
        }
        if self.match_threshold > 255 {
            return bad_parameter(
                "ogale.match_threshold",
                format!("= {} must be at most 255", self.match_threshold),
            );
        }
        if self.edge_threshold > 255 {
            return bad_parameter(
                "ogale.edge_threshold",
                format!("= {} must be at most 255", self.edge_threshold),
            );
        }
        check_uniqueness(self.uniqueness_pct)?;
        if self.vertical_search_px > MAX_VERTICAL_SEARCH_PX {
            return bad_parameter(
                "ogale.vertical_search_px",
                format!(
                    "= {} px must be at most {MAX_VERTICAL_SEARCH_PX}",
                    self.vertical_search_px
                ),
            );
        }
        if self.stretch.is_empty() {
            return bad_parameter(
                "ogale.stretch",
                "needs at least one factor (1.0 = fronto-parallel)",
            );
        }
        for &m in &self.stretch {
            if !m.is_finite() || !(MIN_STRETCH..=MAX_STRETCH).contains(&m) {
                return bad_parameter(
                    "ogale.stretch",
                    format!("factor {m} must be in {MIN_STRETCH}..={MAX_STRETCH}"),
                );
            }
        }
        Ok(())
    }
}

/// One matching hypothesis: left `x` against column `x - s` of the right image resampled with
/// factor `m` (right position `m * (x - s)`), valid on columns `xa..xb` of every row.
#[derive(Debug, Clone, Copy)]
struct Hypothesis {
    /// Index of the resampled right image.
    image: usize,
    /// Whether the factor is exactly 1 (disparity `s` everywhere).
    unit: bool,
    /// Shift in resampled columns.
    s: isize,
    /// First valid column.
    xa: usize,
    /// One past the last valid column.
    xb: usize,
}

/// The right image resampled with one stretch factor, prepared for matching.
#[derive(Debug, Default)]
struct RightImage {
    /// Stretch factor.
    m: f32,
    /// Width (resampled columns `x'` with `m * x' <= w - 1`).
    w: usize,
    /// Grey values.
    grey: Vec<u8>,
    /// `2*R`, `R + min(R)`, `R + max(R)` over the match function's neighbourhood.
    v2: Vec<u16>,
    lo2: Vec<u16>,
    hi2: Vec<u16>,
    /// Census strings (only with [`MatchFunction::Census`]).
    census: Vec<u32>,
    /// Original right position of every resampled column, 1/256 px: `round(256 * m * x')`.
    pos_q8: Vec<i32>,
}

/// The images prepared for matching, and the hypotheses.
#[derive(Debug, Default)]
struct Prepared {
    w: usize,
    h: usize,
    match_fn: MatchFunction,
    vertical_search: usize,
    /// Left `2*L`, `L + min(L)`, `L + max(L)`.
    l2: Vec<u16>,
    llo2: Vec<u16>,
    lhi2: Vec<u16>,
    /// Left census strings (only with [`MatchFunction::Census`]).
    lcensus: Vec<u32>,
    /// One right image per distinct stretch factor, fronto-parallel first.
    right: Vec<RightImage>,
    /// Per row boundary `y | y+1`: prefix counts of uncut vertical links (`w + 1` per boundary).
    uncut_prefix: Vec<u32>,
    /// Per row boundary `y | y+1`: 1.0 where the vertical link holds, 0.0 where it is cut.
    link: Vec<f32>,
    hyps: Vec<Hypothesis>,
    /// Scratch.
    resampled: Vec<u8>,
    tmp: Vec<u8>,
    tmp_min: Vec<u8>,
    tmp_max: Vec<u8>,
}

impl Prepared {
    fn prepare(&mut self, left: &[u8], right: &[u8], w: usize, h: usize, p: &OgaleParams) {
        self.w = w;
        self.h = h;
        self.match_fn = p.match_fn;
        self.vertical_search = p.vertical_search_px as usize;
        let f = p.match_fn;
        intervals(
            left,
            w,
            h,
            f,
            &mut self.tmp,
            &mut self.tmp_min,
            &mut self.tmp_max,
        );
        fill_intervals(
            left,
            &self.tmp_min,
            &self.tmp_max,
            &mut self.l2,
            &mut self.llo2,
            &mut self.lhi2,
        );
        if f == MatchFunction::Census {
            self.lcensus.resize(w * h, 0);
            crate::census::census(left, w, h, CENSUS_WIN, CENSUS_WIN, &mut self.lcensus);
        }
        let mut factors: Vec<f32> = Vec::new();
        for &m in &p.stretch {
            if !factors.iter().any(|&g| (g - m).abs() < 1e-6) {
                factors.push(m);
            }
        }
        // Fronto-parallel first: ties between equal goodness go to the smaller slant.
        factors.sort_by(|a, b| (a - 1.0).abs().total_cmp(&(b - 1.0).abs()));
        self.right.resize_with(factors.len(), RightImage::default);
        for (img, &m) in self.right.iter_mut().zip(&factors) {
            let unit = (m - 1.0).abs() < 1e-6;
            let m = if unit { 1.0 } else { m };
            // Resampled columns x' with m * x' <= w - 1.
            let wr = if unit {
                w
            } else {
                ((w - 1) as f64 / m as f64).floor() as usize + 1
            };
            img.m = m;
            img.w = wr;
            img.pos_q8.clear();
            img.pos_q8
                .extend((0..wr).map(|x| (256.0 * m as f64 * x as f64).round() as i32));
            if unit {
                img.grey.clear();
                img.grey.extend_from_slice(right);
            } else {
                resample(right, w, h, &img.pos_q8, &mut self.resampled);
                std::mem::swap(&mut img.grey, &mut self.resampled);
            }
            intervals(
                &img.grey,
                wr,
                h,
                f,
                &mut self.tmp,
                &mut self.tmp_min,
                &mut self.tmp_max,
            );
            fill_intervals(
                &img.grey,
                &self.tmp_min,
                &self.tmp_max,
                &mut img.v2,
                &mut img.lo2,
                &mut img.hi2,
            );
            if f == MatchFunction::Census {
                img.census.resize(wr * h, 0);
                crate::census::census(&img.grey, wr, h, CENSUS_WIN, CENSUS_WIN, &mut img.census);
            }
        }
        self.edges(left, p);
        self.hypotheses(p);
    }

    /// Horizontal edges of the left image: the link between `(x, y)` and `(x, y+1)` is cut
    /// when `|dy| > edge_threshold` and `|dy| > |dx|`, with `dy = L(x,y+1) - L(x,y)` and `dx`
    /// the central horizontal difference averaged over both rows (halved to a 1-px step).
    fn edges(&mut self, left: &[u8], p: &OgaleParams) {
        let (w, h) = (self.w, self.h);
        let rows = h.saturating_sub(1);
        self.uncut_prefix.clear();
        self.uncut_prefix.resize(rows * (w + 1), 0);
        self.link.clear();
        self.link.resize(rows * w, 1.0);
        let te = p.edge_threshold as i32;
        for y in 0..rows {
            let (a, b) = (&left[y * w..(y + 1) * w], &left[(y + 1) * w..(y + 2) * w]);
            let pre = &mut self.uncut_prefix[y * (w + 1)..(y + 1) * (w + 1)];
            let link = &mut self.link[y * w..(y + 1) * w];
            let mut count = 0u32;
            for x in 0..w {
                let cut = p.cut_horizontal_edges && {
                    let dy = (b[x] as i32 - a[x] as i32).abs();
                    let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
                    let dx4 = (a[xr] as i32 + b[xr] as i32 - a[xl] as i32 - b[xl] as i32).abs();
                    // |dx| = dx4 / 4 (two rows, two-pixel step).
                    dy > te && 4 * dy > dx4
                };
                if cut {
                    link[x] = 0.0;
                } else {
                    count += 1;
                }
                pre[x + 1] = count;
            }
        }
    }

    /// Every `(m, s)` that puts some column inside the disparity range, with its columns.
    fn hypotheses(&mut self, p: &OgaleParams) {
        let w = self.w;
        self.hyps.clear();
        let (dmin, dmax) = (256 * p.min_disp as i64, 256 * p.max_disp as i64);
        for (t, img) in self.right.iter().enumerate() {
            let m = img.m as f64;
            // d(x) = (1 - m) x + m s; (1 - m) x spans lo..=hi over the image.
            let a = (1.0 - m) * (w - 1) as f64;
            let (lo, hi) = (a.min(0.0), a.max(0.0));
            let s_min = ((p.min_disp as f64 - hi) / m).floor() as isize - 1;
            let s_max = ((p.max_disp as f64 - lo) / m).ceil() as isize + 1;
            for s in s_min..=s_max {
                let valid = |x: usize| {
                    let xr = x as isize - s;
                    xr >= 0
                        && (xr as usize) < img.w
                        && (dmin..=dmax)
                            .contains(&(256 * x as i64 - img.pos_q8[xr as usize] as i64))
                };
                let Some(xa) = (0..w).find(|&x| valid(x)) else {
                    continue;
                };
                let xb = (xa..w).rev().find(|&x| valid(x)).map_or(xa, |x| x + 1);
                self.hyps.push(Hypothesis {
                    image: t,
                    unit: img.m == 1.0,
                    s,
                    xa,
                    xb,
                });
            }
        }
    }

    /// Dissimilarity of left row `y` under `hyp` into `out[xa..xb]`: `4 * BT` (in quarter grey
    /// levels) or the census Hamming distance, the smallest over the searched right rows.
    #[inline]
    fn cost_row(&self, y: usize, hyp: &Hypothesis, out: &mut [u16], tmp: &mut Vec<u16>) {
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
    fn disparity_at(&self, hyp: &Hypothesis, x: usize) -> (i32, usize) {
        let pos = self.right[hyp.image].pos_q8[(x as isize - hyp.s) as usize];
        let d_q8 = 256 * x as i32 - pos;
        (d_q8, (x as i32 - ((d_q8 + 128) >> 8)) as usize)
    }

    /// Subpixel offset, in original right px, of the minimum of a parabola through the 5x3 SAD
    /// at the hypothesis' resampled right column moved by -1, 0, +1 (0 near the borders).
    fn subpixel_offset(&self, left: &[u8], hyp: &Hypothesis, x: usize, y: usize) -> f32 {
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

/// Resamples every row of `img` (width `w`) at the positions `pos_q8` (1/256 px, all within
/// `0..=256 * (w - 1)`) with linear interpolation.
fn resample(img: &[u8], w: usize, h: usize, pos_q8: &[i32], out: &mut Vec<u8>) {
    let wr = pos_q8.len();
    out.clear();
    out.resize(wr * h, 0);
    for (row, orow) in img.chunks_exact(w).zip(out.chunks_exact_mut(wr)) {
        for (o, &pq) in orow.iter_mut().zip(pos_q8) {
            let (i, f) = ((pq >> 8) as usize, pq & 255);
            let a = row[i] as i32;
            let b = row[(i + 1).min(w - 1)] as i32;
            *o = ((a * (256 - f) + b * f + 128) >> 8) as u8;
        }
    }
}

/// Min and max of `img` over the neighbourhood of `f` (none, 1x3 or 3x3), borders clamped.
fn intervals(
    img: &[u8],
    w: usize,
    h: usize,
    f: MatchFunction,
    tmp: &mut Vec<u8>,
    lo: &mut Vec<u8>,
    hi: &mut Vec<u8>,
) {
    for (out, max) in [(&mut *lo, false), (&mut *hi, true)] {
        let pick = |a: u8, b: u8| if max { a.max(b) } else { a.min(b) };
        out.clear();
        if matches!(f, MatchFunction::AbsDiff | MatchFunction::Census) {
            // (Census needs no intervals; the arrays stay consistent but unused.)
            out.extend_from_slice(img);
            continue;
        }
        let horizontal = if f == MatchFunction::Bt1x3 {
            &mut *out
        } else {
            &mut *tmp
        };
        horizontal.clear();
        horizontal.resize(w * h, 0);
        for (row, t) in img.chunks_exact(w).zip(horizontal.chunks_exact_mut(w)) {
            for x in 0..w {
                t[x] = pick(
                    pick(row[x.saturating_sub(1)], row[x]),
                    row[(x + 1).min(w - 1)],
                );
            }
        }
        if f == MatchFunction::Bt3x3 {
            out.resize(w * h, 0);
            for y in 0..h {
                let (ya, yb) = (y.saturating_sub(1), (y + 1).min(h - 1));
                for x in 0..w {
                    out[y * w + x] = pick(pick(tmp[ya * w + x], tmp[y * w + x]), tmp[yb * w + x]);
                }
            }
        }
    }
}

/// `v2 = 2 I`, `lo2 = I + min`, `hi2 = I + max` (doubled half-interval bounds).
fn fill_intervals(
    img: &[u8],
    min: &[u8],
    max: &[u8],
    v2: &mut Vec<u16>,
    lo2: &mut Vec<u16>,
    hi2: &mut Vec<u16>,
) {
    v2.clear();
    v2.extend(img.iter().map(|&v| 2 * v as u16));
    lo2.clear();
    lo2.extend(img.iter().zip(min).map(|(&v, &m)| v as u16 + m as u16));
    hi2.clear();
    hi2.extend(img.iter().zip(max).map(|(&v, &m)| v as u16 + m as u16));
}

/// Writes `right` mapped to the mean and standard deviation of `left` (rounded, saturated).
/// A flat right image is only shifted to the left's mean.
fn equalize_mean_std(left: &[u8], right: &[u8], out: &mut [u8]) {
    let stats = |d: &[u8]| {
        let mut hist = [0u64; 256];
        for &v in d {
            hist[v as usize] += 1;
        }
        let n = d.len().max(1) as f64;
        let mean = hist
            .iter()
            .enumerate()
            .map(|(v, &c)| v as f64 * c as f64)
            .sum::<f64>()
            / n;
        let var = hist
            .iter()
            .enumerate()
            .map(|(v, &c)| (v as f64 - mean).powi(2) * c as f64)
            .sum::<f64>()
            / n;
        (mean, var.sqrt())
    };
    let (ml, sl) = stats(left);
    let (mr, sr) = stats(right);
    let gain = if sr > 1e-9 { sl / sr } else { 1.0 };
    let mut lut = [0u8; 256];
    for (v, slot) in lut.iter_mut().enumerate() {
        *slot = ((v as f64 - mr) * gain + ml).round().clamp(0.0, 255.0) as u8;
    }
    for (o, &v) in out.iter_mut().zip(right) {
        *o = lut[v as usize];
    }
}

/// Winner-take-all state of one left pixel.
#[derive(Debug, Clone, Copy)]
struct LeftBest {
    /// Best goodness (0 = none yet).
    g: f32,
    /// Best goodness among hypotheses more than 1 px from the best.
    second: f32,
    /// Disparity of the best hypothesis, 1/256 px.
    d: i32,
    /// Index of the best hypothesis.
    h: u32,
}

/// What a right pixel has granted so far.
#[derive(Debug, Clone, Copy)]
struct RightGrant {
    /// Goodness of the grant (0 = none).
    g: f32,
    /// Its disparity, 1/256 px.
    d: i32,
}

/// A disparity no hypothesis can have (far from every real one).
const NO_DISP: i32 = i32::MIN / 4;

/// Winner-take-all state with two-sided uniqueness.
#[derive(Debug, Default)]
struct Wta {
    left: Vec<LeftBest>,
    right: Vec<RightGrant>,
    /// Hypotheses further apart than this (1/256 px) are rivals in the ambiguity test.
    rival_q8: i32,
}

impl Wta {
    /// Clears the state for `n` pixels; `max_stretch` is the largest stretch factor, which is
    /// also the spacing of neighbouring shifts in px.
    fn reset(&mut self, n: usize, max_stretch: f32) {
        // Neighbouring shifts (spacing m px) are never rivals: more than m + 1/2 px apart.
        self.rival_q8 = (256.0 * (max_stretch.max(1.0) + 0.5)).round() as i32;
        let none = LeftBest {
            g: 0.0,
            second: 0.0,
            d: NO_DISP,
            h: u32::MAX,
        };
        self.left.clear();
        self.left.resize(n, none);
        self.right.clear();
        self.right.resize(n, RightGrant { g: 0.0, d: NO_DISP });
    }

    /// Left pixel `p` (index) may match right pixel `q` (index) with goodness `g` at disparity
    /// `d_q8` under hypothesis `h`: it takes it when `g` beats both its own best and the grant
    /// of `q`; every hypothesis far enough from the best (a rival) feeds the ambiguity test.
    #[inline(always)]
    fn offer(&mut self, p: usize, q: usize, g: f32, d_q8: i32, h: u32) {
        let l = &mut self.left[p];
        let far = (d_q8 - l.d).abs() > self.rival_q8;
        if g > l.g {
            let r = &mut self.right[q];
            if g > r.g {
                let second = if far { l.second.max(l.g) } else { l.second };
                *l = LeftBest {
                    g,
                    second,
                    d: d_q8,
                    h,
                };
                *r = RightGrant { g, d: d_q8 };
                return;
            }
        }
        if far && g > l.second {
            l.second = g;
        }
    }
}

/// Scratch of the components variant.
#[derive(Debug, Default)]
struct Components {
    cost: Vec<u16>,
    cost_tmp: Vec<u16>,
    /// Match bits of one row (bit `x % 64` of word `x / 64`).
    bits: Vec<u64>,
    /// Runs `(x0, x1)` (x1 exclusive) of matching pixels, row by row.
    runs: Vec<(u16, u16)>,
    /// First run of every row (`h + 1` entries).
    row_start: Vec<u32>,
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl Components {
    /// One hypothesis: binary matches, runs, run-length union-find, then every matching pixel
    /// offers its component size (in left pixels) to the winner-take-all.
    fn run(&mut self, prep: &Prepared, hi: usize, thr: u16, cut: bool, wta: &mut Wta) {
        let hyp = prep.hyps[hi];
        let (w, h) = (prep.w, prep.h);
        let words = w.div_ceil(64);
        self.cost.resize(words * 64, u16::MAX);
        self.bits.resize(words, 0);
        self.runs.clear();
        self.row_start.clear();
        let (wa, wb) = (hyp.xa / 64, hyp.xb.div_ceil(64));
        for y in 0..h {
            self.row_start.push(self.runs.len() as u32);
            prep.cost_row(y, &hyp, &mut self.cost, &mut self.cost_tmp);
            // Pack the matches into bits; the band mask drops columns outside xa..xb.
            for (k, word) in self.bits[wa..wb].iter_mut().enumerate() {
                let chunk = &self.cost[(wa + k) * 64..(wa + k + 1) * 64];
                let mut v = 0u64;
                for (i, &c) in chunk.iter().enumerate() {
                    v |= u64::from(c <= thr) << i;
                }
                *word = v;
            }
            // Runs from the bits: alternately the next set and the next clear bit.
            let mut start: Option<usize> = None;
            for k in wa..wb {
                let lo = hyp.xa.max(k * 64) - k * 64;
                let hi = hyp.xb.min(k * 64 + 64) - k * 64;
                let band = if hi == 64 { u64::MAX } else { (1u64 << hi) - 1 } & (u64::MAX << lo);
                let v = self.bits[k] & band;
                let mut pos = 0u32;
                while pos < 64 {
                    let rest = if start.is_none() { v >> pos } else { !v >> pos };
                    if rest == 0 {
                        break;
                    }
                    pos += rest.trailing_zeros();
                    let x = k * 64 + pos as usize;
                    match start {
                        None => start = Some(x),
                        Some(x0) => {
                            self.runs.push((x0 as u16, x as u16));
                            start = None;
                        }
                    }
                }
            }
            if let Some(x0) = start {
                self.runs.push((x0 as u16, hyp.xb as u16));
            }
        }
        self.row_start.push(self.runs.len() as u32);
        let nr = self.runs.len();
        self.parent.clear();
        self.parent.extend(0..nr as u32);
        // Vertical links between overlapping runs of consecutive rows, unless every column of
        // the overlap is cut by a horizontal edge.
        for y in 1..h {
            let (a0, a1) = (self.row_start[y - 1] as usize, self.row_start[y] as usize);
            let b1 = self.row_start[y + 1] as usize;
            let (mut i, mut j) = (a0, a1);
            let pre = cut.then(|| &prep.uncut_prefix[(y - 1) * (w + 1)..y * (w + 1)]);
            while i < a1 && j < b1 {
                let (ra, rb) = (self.runs[i], self.runs[j]);
                let (lo, hi) = (ra.0.max(rb.0) as usize, ra.1.min(rb.1) as usize);
                if lo < hi && pre.is_none_or(|pre| pre[hi] > pre[lo]) {
                    union(&mut self.parent, i as u32, j as u32);
                }
                if ra.1 < rb.1 {
                    i += 1;
                } else {
                    j += 1;
                }
            }
        }
        // Component sizes in pixels, kept at the roots.
        self.size.clear();
        self.size.resize(nr, 0);
        for r in 0..nr {
            let root = find(&mut self.parent, r as u32) as usize;
            self.parent[r] = root as u32;
            let (x0, x1) = self.runs[r];
            self.size[root] += (x1 - x0) as u32;
        }
        for y in 0..h {
            let row = y * w;
            for r in self.row_start[y] as usize..self.row_start[y + 1] as usize {
                let g = self.size[self.parent[r] as usize] as f32;
                let (x0, x1) = (self.runs[r].0 as usize, self.runs[r].1 as usize);
                if hyp.unit {
                    let (d_q8, s) = (256 * hyp.s as i32, hyp.s as usize);
                    for x in x0..x1 {
                        wta.offer(row + x, row + x - s, g, d_q8, hi as u32);
                    }
                } else {
                    for x in x0..x1 {
                        let (d_q8, q) = prep.disparity_at(&hyp, x);
                        wta.offer(row + x, row + q, g, d_q8, hi as u32);
                    }
                }
            }
        }
    }
}

/// Union-find root with path halving.
#[inline]
fn find(parent: &mut [u32], mut a: u32) -> u32 {
    while parent[a as usize] != a {
        let gp = parent[parent[a as usize] as usize];
        parent[a as usize] = gp;
        a = gp;
    }
    a
}

/// Joins the sets of `a` and `b` (the smaller root index becomes the root).
#[inline]
fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        parent[hi as usize] = lo;
    }
}

/// Scratch of the diffusion variant.
#[derive(Debug, Default)]
struct Diffusion {
    cost: Vec<u16>,
    cost_tmp: Vec<u16>,
    /// Soft match of every pixel.
    m: Vec<f32>,
    /// Vertical support of every pixel.
    v: Vec<f32>,
    /// Running sums across a row of columns.
    acc: Vec<f32>,
    /// Horizontal support of one row.
    hrow: Vec<f32>,
    /// Soft match of every cost: `exp(-alpha/255 * c/4)` (c = 4 x BT) or `exp(-beta * c)`
    /// (c = Hamming distance).
    lut: Vec<f32>,
    /// The match function `lut` was built for.
    lut_for: Option<MatchFunction>,
}

impl Diffusion {
    fn prepare_lut(&mut self, f: MatchFunction) {
        if self.lut_for != Some(f) {
            self.lut = if f == MatchFunction::Census {
                (0..=32).map(|c| (-CENSUS_BETA * c as f32).exp()).collect()
            } else {
                // Cost c is 4 x BT, BT at most 255.
                (0..=4 * 255 + 4)
                    .map(|c| (-(DIFFUSION_ALPHA / 255.0) * c as f32 / 4.0).exp())
                    .collect()
            };
            self.lut_for = Some(f);
        }
    }

    /// One hypothesis: soft matches, two-pass recursive diffusion along columns (cut at
    /// horizontal edges) and rows, goodness = row support x column support.
    fn run(&mut self, prep: &Prepared, hi: usize, wta: &mut Wta) {
        let hyp = prep.hyps[hi];
        let (w, h) = (prep.w, prep.h);
        let (xa, xb) = (hyp.xa, hyp.xb);
        self.cost.resize(w, 0);
        self.m.resize(w * h, 0.0);
        self.v.resize(w * h, 0.0);
        self.acc.resize(w, 0.0);
        self.hrow.resize(w, 0.0);
        let top = self.lut.len() - 1;
        for y in 0..h {
            prep.cost_row(y, &hyp, &mut self.cost, &mut self.cost_tmp);
            let m = &mut self.m[y * w + xa..y * w + xb];
            for (mv, &c) in m.iter_mut().zip(&self.cost[xa..xb]) {
                *mv = self.lut[(c as usize).min(top)];
            }
        }
        // Columns, forward: a = M + a * M * link(y-1 | y).
        let acc = &mut self.acc[xa..xb];
        for y in 0..h {
            let m = &self.m[y * w + xa..y * w + xb];
            let v = &mut self.v[y * w + xa..y * w + xb];
            if y == 0 {
                acc.copy_from_slice(m);
                v.copy_from_slice(m);
            } else {
                let link = &prep.link[(y - 1) * w + xa..(y - 1) * w + xb];
                for (((a, &mv), vv), &lk) in acc.iter_mut().zip(m).zip(v.iter_mut()).zip(link) {
                    *a = mv + *a * mv * lk;
                    *vv = *a;
                }
            }
        }
        // Columns, backward: t = b * M * link(y | y+1); V += t; b = t + M.
        for y in (0..h).rev() {
            let m = &self.m[y * w + xa..y * w + xb];
            let v = &mut self.v[y * w + xa..y * w + xb];
            if y + 1 == h {
                acc.copy_from_slice(m);
            } else {
                let link = &prep.link[y * w + xa..y * w + xb];
                for (((b, &mv), vv), &lk) in acc.iter_mut().zip(m).zip(v.iter_mut()).zip(link) {
                    let t = *b * mv * lk;
                    *vv += t;
                    *b = t + mv;
                }
            }
        }
        // Rows, then the goodness of every pixel.
        for y in 0..h {
            let row = y * w;
            let m = &self.m[row + xa..row + xb];
            let hr = &mut self.hrow[xa..xb];
            let mut a = 0.0f32;
            for (hv, &mv) in hr.iter_mut().zip(m) {
                a = mv + a * mv;
                *hv = a;
            }
            let mut b = 0.0f32;
            for (hv, &mv) in hr.iter_mut().zip(m).rev() {
                let t = b * mv;
                *hv += t;
                b = t + mv;
            }
            let v = &self.v[row + xa..row + xb];
            for (k, (&hv, &vv)) in hr.iter().zip(v).enumerate() {
                let g = hv * vv;
                if g >= DIFFUSION_MIN_GOODNESS {
                    let x = xa + k;
                    let (d_q8, q) = prep.disparity_at(&hyp, x);
                    wta.offer(row + x, row + q, g, d_q8, hi as u32);
                }
            }
        }
    }
}

/// Ogale & Aloimonos matcher with reusable scratch buffers.
#[derive(Debug)]
pub struct OgaleMatcher {
    params: OgaleParams,
    right_eq: Vec<u8>,
    prep: Prepared,
    wta: Wta,
    cc: Components,
    diff: Diffusion,
    right_q8: Vec<u16>,
    median: Vec<u16>,
    labels: Vec<u32>,
    stack: Vec<u32>,
}

impl OgaleMatcher {
    /// Builds the matcher from a config section (see [`OgaleParams::from_config`]).
    pub fn from_config(config: &StereoConfig) -> Result<Self, StereoError> {
        Self::new(OgaleParams::from_config(config))
    }

    /// Creates a matcher; fails on an empty or too large disparity range or a bad parameter.
    pub fn new(params: OgaleParams) -> Result<Self, StereoError> {
        params.validate()?;
        Ok(Self {
            params,
            right_eq: Vec::new(),
            prep: Prepared::default(),
            wta: Wta::default(),
            cc: Components::default(),
            diff: Diffusion::default(),
            right_q8: Vec::new(),
            median: Vec::new(),
            labels: Vec::new(),
            stack: Vec::new(),
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &OgaleParams {
        &self.params
    }

    /// Winner-take-all result to the output map: ambiguity test, subpixel fit, 3x3 median,
    /// left-right check (occlusions), speckle filter.
    fn finish(&mut self, left: &[u8], out_q8: &mut [u16]) -> MatchStats {
        let p = &self.params;
        let (w, h) = (self.prep.w, self.prep.h);
        let keep = |best: f32, second: f32| -> bool {
            best > 0.0
                && (p.uniqueness_pct == 0
                    || second * 100.0 < best * (100 - p.uniqueness_pct) as f32)
        };
        // Left of this column fewer than two rival disparities fit in the image, so the
        // ambiguity test cannot be made: those pixels stay invalid.
        let x_min = if p.uniqueness_pct > 0 {
            p.min_disp as usize + (self.wta.rival_q8 / 256) as usize + 1
        } else {
            0
        };
        for (i, o) in out_q8.iter_mut().enumerate() {
            let b = self.wta.left[i];
            *o = if i % w >= x_min && keep(b.g, b.second) {
                let mut d = b.d as f32;
                if p.subpixel {
                    let hyp = &self.prep.hyps[b.h as usize];
                    d -= 256.0 * self.prep.subpixel_offset(left, hyp, i % w, i / w);
                }
                d.round().clamp(1.0, u16::MAX as f32) as u16
            } else {
                0
            };
        }
        if MEDIAN_BEFORE_LR {
            self.median.resize(out_q8.len(), 0);
            median3x3(out_q8, w, h, &mut self.median);
            out_q8.copy_from_slice(&self.median);
        }
        if p.lr_check {
            self.right_q8.clear();
            self.right_q8.extend(self.wta.right.iter().map(|r| {
                if r.d == NO_DISP {
                    0
                } else {
                    r.d.clamp(1, u16::MAX as i32) as u16
                }
            }));
            if MEDIAN_BEFORE_LR {
                self.median.resize(out_q8.len(), 0);
                median3x3(&self.right_q8, w, h, &mut self.median);
                std::mem::swap(&mut self.right_q8, &mut self.median);
            }
            lr_check(out_q8, &self.right_q8, w, p.lr_max_diff_px);
        }
        if p.speckle_window_px > 0 {
            speckle_filter(
                out_q8,
                w,
                h,
                p.speckle_window_px as usize,
                p.speckle_range_px,
                &mut self.labels,
                &mut self.stack,
            );
        }
        MatchStats {
            valid_px: out_q8.iter().filter(|&&d| d != 0).count() as u32,
            row_align: None,
        }
    }
}

impl StereoMatcher for OgaleMatcher {
    fn algorithm(&self) -> StereoAlgorithm {
        StereoAlgorithm::Ogale
    }

    fn compute(
        &mut self,
        left: ImageView<'_>,
        right: ImageView<'_>,
        out_q8: &mut [u16],
    ) -> Result<MatchStats, StereoError> {
        check_pair(&left, &right, out_q8.len())?;
        // The views' fields are public: make sure the buffers really hold the pixels.
        ImageView::new(left.data, left.width, left.height)?;
        ImageView::new(right.data, right.width, right.height)?;
        let (w, h) = (left.width, left.height);
        let p = &self.params;
        check_fits(&left, p.max_disp, 1)?;
        if w > MAX_WIDTH_PX {
            return Err(StereoError::ImageTooWide {
                width: w,
                max_width: MAX_WIDTH_PX,
            });
        }
        let n = w * h;
        self.right_eq.resize(n, 0);
        match p.equalization {
            Equalization::Off => self.right_eq.copy_from_slice(right.data),
            Equalization::SumRatio => {
                equalize_right(left.data, right.data, &mut self.right_eq);
            }
            Equalization::MeanStd => equalize_mean_std(left.data, right.data, &mut self.right_eq),
        }
        self.prep.prepare(left.data, &self.right_eq, w, h, p);
        let max_stretch = self.prep.right.iter().map(|r| r.m).fold(1.0f32, f32::max);
        self.wta.reset(n, max_stretch);
        match p.variant {
            OgaleVariant::Components => {
                let thr = match p.match_fn {
                    MatchFunction::Census => p.match_threshold as u16,
                    _ => (4 * p.match_threshold) as u16,
                };
                for hi in 0..self.prep.hyps.len() {
                    self.cc
                        .run(&self.prep, hi, thr, p.cut_horizontal_edges, &mut self.wta);
                }
            }
            OgaleVariant::Diffusion => {
                self.diff.prepare_lut(p.match_fn);
                for hi in 0..self.prep.hyps.len() {
                    self.diff.run(&self.prep, hi, &mut self.wta);
                }
            }
        }
        Ok(self.finish(left.data, out_q8))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{SyntheticPair, flatten_region, plane, score, texture_at};

    fn params(min_disp: u32, max_disp: u32) -> OgaleParams {
        OgaleParams {
            min_disp,
            max_disp,
            ..OgaleParams::default()
        }
    }

    fn run(p: &OgaleParams, pair: &SyntheticPair) -> Vec<u16> {
        let mut m = OgaleMatcher::new(p.clone()).expect("valid params");
        let (w, h) = (pair.width, pair.height);
        let mut out = vec![0u16; w * h];
        let l = ImageView::new(&pair.left, w, h).expect("left");
        let r = ImageView::new(&pair.right, w, h).expect("right");
        m.compute(l, r, &mut out).expect("compute");
        out
    }

    /// Shares of the pixels selected by `pick` (with known disparity) that are within `tol` px,
    /// invalid, and wrong (valid but off by more than `tol`).
    fn shares(
        pair: &SyntheticPair,
        out: &[u16],
        tol: f32,
        pick: impl Fn(usize, usize) -> bool,
    ) -> (f32, f32, f32) {
        let (mut n, mut good, mut invalid, mut wrong) = (0, 0, 0, 0);
        for y in 0..pair.height {
            for x in 0..pair.width {
                let i = y * pair.width + x;
                let truth = pair.disparity_px[i];
                if !truth.is_finite() || !pick(x, y) {
                    continue;
                }
                n += 1;
                match crate::q8_to_px(out[i]) {
                    None => invalid += 1,
                    Some(d) if (d - truth).abs() <= tol => good += 1,
                    Some(_) => wrong += 1,
                }
            }
        }
        let n = n.max(1) as f32;
        (good as f32 / n, invalid as f32 / n, wrong as f32 / n)
    }

    /// A textured background at `d_bg` with a nearer textured box (columns `x0..x1`, all rows)
    /// at `d_fg`. Background pixels hidden in the right image by the box are NaN.
    fn two_planes(w: usize, h: usize, d_bg: f32, d_fg: f32, x0: usize, x1: usize) -> SyntheticPair {
        let mut p = plane(w, h, 0.0, 0.0, d_bg, 11);
        let in_box = |u: f32| u >= x0 as f32 && u < x1 as f32;
        for y in 0..h {
            for x in 0..w {
                let (i, xf, yf) = (y * w + x, x as f32, y as f32);
                if in_box(xf) {
                    p.left[i] = texture_at(xf, yf, 99) as u8;
                    p.disparity_px[i] = if xf - d_fg >= 0.0 { d_fg } else { f32::NAN };
                } else {
                    p.left[i] = texture_at(xf, yf, 11) as u8;
                    let hidden = in_box(xf - d_bg + d_fg);
                    p.disparity_px[i] = if xf - d_bg < 0.0 || hidden {
                        f32::NAN
                    } else {
                        d_bg
                    };
                }
                // The right image shows the box where it covers the background.
                p.right[i] = if in_box(xf + d_fg) {
                    texture_at(xf + d_fg, yf, 99) as u8
                } else {
                    texture_at(xf + d_bg, yf, 11) as u8
                };
            }
        }
        p
    }

    /// Two horizontally striped surfaces stacked vertically: bands of 2 rows of one grey level
    /// (neighbouring bands differ by at least 25) with sparse 1-px vertical ticks. Rows
    /// `0..h/2` lie at `d_top`, the others at `d_bottom`.
    fn striped(w: usize, h: usize, d_top: f32, d_bottom: f32) -> SyntheticPair {
        let tex = |u: usize, y: usize| -> u8 {
            let band = y / 2;
            let grey = 60 + ((band * 6) % 7) as u32 * 25;
            let hash = (u as u32).wrapping_mul(2_654_435_761) ^ (band as u32).wrapping_mul(40_503);
            if (hash >> 7).is_multiple_of(9) {
                if grey > 128 {
                    (grey - 70) as u8
                } else {
                    (grey + 70) as u8
                }
            } else {
                grey as u8
            }
        };
        let mut left = vec![0u8; w * h];
        let mut right = vec![0u8; w * h];
        let mut disparity_px = vec![f32::NAN; w * h];
        for y in 0..h {
            let d = if y < h / 2 { d_top } else { d_bottom };
            for x in 0..w {
                left[y * w + x] = tex(x, y);
                right[y * w + x] = tex(x + d as usize, y);
                if x as f32 >= d {
                    disparity_px[y * w + x] = d;
                }
            }
        }
        SyntheticPair {
            width: w,
            height: h,
            left,
            right,
            disparity_px,
        }
    }

    #[test]
    fn fronto_parallel_plane_is_recovered() {
        let pair = plane(160, 100, 0.0, 0.0, 20.0, 1);
        for variant in [OgaleVariant::Components, OgaleVariant::Diffusion] {
            let p = params(5, 40).with_variant(variant);
            let out = run(&p, &pair);
            let (good, dense) = score(&pair, &out, 1.0, 40);
            println!("fronto {variant:?}: good {good} dense {dense}");
            assert!(good > 0.97, "{variant:?}: good {good} dense {dense}");
        }
    }

    #[test]
    fn two_planes_are_recovered_and_the_occluded_strip_is_invalid() {
        let (d_bg, d_fg, x0, x1) = (10.0, 30.0, 90, 170);
        let pair = two_planes(240, 120, d_bg, d_fg, x0, x1);
        for variant in [OgaleVariant::Components, OgaleVariant::Diffusion] {
            let out = run(&params(5, 40).with_variant(variant), &pair);
            let fg = shares(&pair, &out, 1.0, |x, _| (x0..x1).contains(&x));
            let bg = shares(&pair, &out, 1.0, |x, _| {
                x >= 30 && !(x0 - 20..x1).contains(&x)
            });
            // The background strip left of the box is hidden from the right camera.
            let strip = x0 - (d_fg - d_bg) as usize..x0;
            let mut occluded = (0usize, 0usize);
            for y in 0..pair.height {
                for x in strip.clone() {
                    occluded.0 += 1;
                    occluded.1 += usize::from(out[y * pair.width + x] == 0);
                }
            }
            let occ_invalid = occluded.1 as f32 / occluded.0 as f32;
            println!("two planes {variant:?}: fg {fg:?} bg {bg:?} occluded invalid {occ_invalid}");
            assert!(
                fg.0 > 0.97 && bg.0 > 0.97,
                "{variant:?}: fg {fg:?} bg {bg:?}"
            );
            assert!(
                occ_invalid > 0.9,
                "{variant:?}: only {occ_invalid} of the occluded strip invalid"
            );
        }
    }

    #[test]
    fn stretch_factors_help_on_a_sideways_slanted_plane() {
        // d(x) = 50 - 0.2 x: a hallway wall seen at an angle (right image stretched by 1.2).
        let pair = plane(200, 80, -0.2, 0.0, 50.0, 2);
        let base = params(5, 55);
        let flat = run(&base, &pair);
        let stretched = run(
            &OgaleParams {
                stretch: vec![0.8, 0.9, 1.0, 1.1, 1.25],
                ..base.clone()
            },
            &pair,
        );
        let (flat_good, flat_dense) = score(&pair, &flat, 0.5, 0);
        let (st_good, st_dense) = score(&pair, &stretched, 0.5, 0);
        let (flat_good2, _) = score(&pair, &flat, 2.0, 0);
        let (st_good2, _) = score(&pair, &stretched, 2.0, 0);
        println!(
            "slant: within 0.5 px {flat_good} -> {st_good}, within 2 px {flat_good2} -> {st_good2}, dense {flat_dense} -> {st_dense}"
        );
        assert!(
            st_good > flat_good + 0.15,
            "within 0.5 px: {flat_good} -> {st_good}"
        );
        assert!(
            st_good2 >= flat_good2,
            "within 2 px: {flat_good2} -> {st_good2}"
        );
    }

    #[test]
    fn textureless_block_is_invalid_rather_than_wrong() {
        let mut pair = plane(200, 80, 0.0, 0.0, 20.0, 3);
        flatten_region(&mut pair, 80, 140, 128);
        for variant in [OgaleVariant::Components, OgaleVariant::Diffusion] {
            let out = run(&params(5, 40).with_variant(variant), &pair);
            let block = shares(&pair, &out, 1.0, |x, _| (80..140).contains(&x));
            println!("flat block {variant:?}: (good, invalid, wrong) {block:?}");
            assert!(
                block.2 < 0.02,
                "{variant:?}: {} of the flat block wrong",
                block.2
            );
        }
        // With nothing to match anywhere, nothing is claimed.
        let flat = SyntheticPair {
            left: vec![90; 120 * 40],
            right: vec![90; 120 * 40],
            ..plane(120, 40, 0.0, 0.0, 10.0, 4)
        };
        for variant in [OgaleVariant::Components, OgaleVariant::Diffusion] {
            let out = run(&params(5, 30).with_variant(variant), &flat);
            let valid = out.iter().filter(|&&d| d != 0).count();
            assert_eq!(
                valid, 0,
                "{variant:?}: {valid} pixels of a blank pair valid"
            );
        }
    }

    #[test]
    fn cutting_vertical_links_at_horizontal_edges_matters() {
        let pair = striped(200, 80, 12.0, 30.0);
        let base = params(5, 40);
        let with_cut = run(&base, &pair);
        let without = run(
            &OgaleParams {
                cut_horizontal_edges: false,
                ..base.clone()
            },
            &pair,
        );
        let (cut_good, cut_dense) = score(&pair, &with_cut, 1.0, 40);
        let (nocut_good, nocut_dense) = score(&pair, &without, 1.0, 40);
        let cut_wrong = cut_dense - cut_good;
        let nocut_wrong = nocut_dense - nocut_good;
        println!(
            "stripes: good {nocut_good} -> {cut_good}, wrong {nocut_wrong} -> {cut_wrong} (without -> with cuts)"
        );
        assert!(cut_good > 0.95, "with cuts only {cut_good} correct");
        assert!(
            cut_good > nocut_good + 0.4,
            "cuts: {nocut_good} -> {cut_good}"
        );
    }

    #[test]
    fn bad_inputs_are_rejected() {
        let ok = params(5, 20);
        let bad = |p: OgaleParams| OgaleMatcher::new(p).expect_err("must be rejected");
        assert!(matches!(
            bad(params(20, 20)),
            StereoError::BadRange { min: 20, max: 20 }
        ));
        assert!(matches!(
            bad(params(0, 300)),
            StereoError::BadParameter { .. }
        ));
        for stretch in [vec![], vec![0.2], vec![f32::NAN], vec![1.0, 3.0]] {
            let p = OgaleParams {
                stretch,
                ..ok.clone()
            };
            assert!(matches!(bad(p), StereoError::BadParameter { .. }));
        }
        let p = OgaleParams {
            match_threshold: 256,
            ..ok.clone()
        };
        assert!(matches!(bad(p), StereoError::BadParameter { .. }));
        let p = OgaleParams {
            vertical_search_px: 3,
            ..ok.clone()
        };
        assert!(matches!(bad(p), StereoError::BadParameter { .. }));
        let config = StereoConfig {
            min_disp: 30,
            max_disp: 10,
            ..StereoConfig::default()
        };
        assert!(matches!(
            OgaleMatcher::from_config(&config),
            Err(StereoError::BadRange { .. })
        ));

        let mut m = OgaleMatcher::new(ok).expect("valid");
        let a = vec![0u8; 64 * 8];
        let b = vec![0u8; 48 * 8];
        let mut out = vec![0u16; 64 * 8];
        fn view(data: &[u8], width: usize, height: usize) -> ImageView<'_> {
            ImageView {
                data,
                width,
                height,
            }
        }
        let err = m
            .compute(view(&a, 64, 8), view(&b, 48, 8), &mut out)
            .expect_err("sizes differ");
        assert!(matches!(err, StereoError::SizeMismatch { .. }));
        let err = m
            .compute(view(&a, 64, 8), view(&a, 64, 8), &mut out[1..])
            .expect_err("output");
        assert!(matches!(err, StereoError::BufferSize { .. }));
        // Views built by hand with too few pixels are caught, not indexed out of bounds.
        let err = m
            .compute(view(&a[1..], 64, 8), view(&a[1..], 64, 8), &mut out)
            .expect_err("data");
        assert!(matches!(err, StereoError::BufferSize { .. }));
        let narrow = vec![0u8; 21 * 8];
        let mut out = vec![0u16; 21 * 8];
        let err = m
            .compute(view(&narrow, 21, 8), view(&narrow, 21, 8), &mut out)
            .expect_err("narrow");
        assert!(matches!(
            err,
            StereoError::ImageTooSmall { max_disp: 20, .. }
        ));
    }

    #[test]
    fn scratch_buffers_are_reused_across_sizes() {
        let small = plane(120, 50, 0.0, 0.0, 15.0, 5);
        let large = plane(180, 70, 0.0, 0.0, 25.0, 6);
        let p = OgaleParams {
            stretch: vec![0.9, 1.0, 1.1],
            ..params(5, 35)
        };
        let mut m = OgaleMatcher::new(p.clone()).expect("valid");
        for pair in [&small, &large, &small] {
            let (w, h) = (pair.width, pair.height);
            let mut out = vec![0u16; w * h];
            let l = ImageView::new(&pair.left, w, h).expect("left");
            let r = ImageView::new(&pair.right, w, h).expect("right");
            let stats = m.compute(l, r, &mut out).expect("compute");
            assert_eq!(
                out,
                run(&p, pair),
                "a reused matcher must give a fresh one's map"
            );
            assert_eq!(
                stats.valid_px as usize,
                out.iter().filter(|&&d| d != 0).count()
            );
        }
        assert_eq!(m.algorithm(), StereoAlgorithm::Ogale);
        let config = StereoConfig {
            algorithm: StereoAlgorithm::Ogale,
            ..StereoConfig::default()
        };
        assert_eq!(
            crate::matcher_for(&config).expect("ogale").algorithm(),
            StereoAlgorithm::Ogale
        );
    }

    #[test]
    fn mean_std_equalisation_undoes_gain_and_offset() {
        let left: Vec<u8> = (0..2000).map(|i| (30 + (i * 7) % 180) as u8).collect();
        let right: Vec<u8> = left
            .iter()
            .map(|&p| (p as f32 * 0.8 + 10.0).round() as u8)
            .collect();
        let mut out = vec![0u8; left.len()];
        equalize_mean_std(&left, &right, &mut out);
        let worst = left
            .iter()
            .zip(&out)
            .map(|(&a, &b)| (a as i32 - b as i32).abs())
            .max();
        assert!(worst.is_some_and(|w| w <= 1), "worst difference {worst:?}");
    }

    #[test]
    fn webcam_defects_are_survived_with_the_robust_options() {
        let mut pair = plane(200, 80, 0.0, 0.0, 20.0, 7);
        crate::synthetic::degrade(&mut pair.right, pair.width, 0.8, 10.0, 4.0, 1, 9);
        let p = OgaleParams {
            equalization: Equalization::MeanStd,
            ..params(5, 40)
        };
        let (good, dense) = score(&pair, &run(&p, &pair), 1.0, 40);
        println!("degraded: good {good} dense {dense}");
        assert!(good > 0.8, "good {good} dense {dense}");
    }
}
