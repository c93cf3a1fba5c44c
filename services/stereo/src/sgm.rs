//! Census + semi-global matching (Hirschmüller, PAMI 2008) with hand-written AVX2 kernels.
//!
//! Pipeline of one frame:
//! 1. optional reference equalisation of the right image ([`crate::equalize`]);
//! 2. a 3x3 box prefilter of both images ([`SgmParams::prefilter`], on by default);
//! 3. 5x5 census of both images ([`crate::census::census`]); the pixel cost is the Hamming
//!    distance (0..=24). A 9x7 centre-symmetric census was tried and was not clearly better;
//! 4. the matching cost: the pixel costs averaged over a `block x block` window (5x5 by
//!    default, OpenCV's `blockSize`) and scaled to 0..=[`COST_MAX`], computed row by row from
//!    a ring of raw cost rows with running column and row sums (`block_costs`). It is what
//!    makes the matcher hold up on raw webcam pairs: on Tsukuba, Venus and Motorcycle with
//!    right-image defects (gain 0.8, +10, noise sigma 4, 1 px vertical shift) and all
//!    filters off, mean bad-2 fell from 23.6 % (pixel census) to 12.1 % (5x5), and the clean
//!    pairs went from 7.0 % to 6.1 % (`tests::tune_penalties`);
//!    then a texture mask: mean |L(x+1) - L(x-1)| of the (prefiltered) left image over a
//!    square window below [`SgmParams::texture_threshold`] → invalid. SGM would otherwise
//!    fill flat regions with disparities propagated from their borders. The default (0.25
//!    grey levels per pixel over 11x11) clears flat areas with noise up to sigma 0.5; with
//!    noise sigma 2 on the left image about 30 % of a flat block stays valid, two thirds of
//!    it wrong, unless the threshold is raised to 1.0 (`tests::flat_block_sweep`), which costs
//!    about 15 points of density on Middlebury;
//! 5. path aggregation `L_r(p,d) = C(p,d) + min(L_r(p-r,d), L_r(p-r,d±1) + P1,
//!    min_k L_r(p-r,k) + P2) - min_k L_r(p-r,k)`, summed over the paths into `S`:
//!    * 5 paths (default): one top-down sweep with row-local buffers only. Per row, a
//!      right-to-left pass computes the costs and the ← path, then a left-to-right pass computes
//!      →, ↓ and both downward diagonals (each from a one-row buffer updated in place) and
//!      sums S; a third loop picks the winners;
//!    * 4 paths (→ ← ↓ ↑) and 8 paths: the top-down sweep stores S (u16) for the whole image,
//!      a bottom-up sweep adds ↑ (and the two upward diagonals) and picks the winners;
//! 6. winner-take-all on S (lowest disparity on ties) and the uniqueness ratio; a left-right
//!    check against a right-view map built the cheap way (OpenCV's): every left winner claims
//!    right pixel `x - d` when its S is the lowest claim so far, then [`crate::post::lr_check`]
//!    on the integer maps; an equiangular subpixel fit on S (measured against
//!    [`crate::post::parabola_offset`]: mean error 0.168 vs 0.209 px on a fronto-parallel
//!    plane, 0.145 vs 0.146 on a slanted one, 0.228 vs 0.235 px on Venus); finally
//!    [`crate::post::speckle_filter`].
//!
//! Borders: a pixel `x` is matched over the disparities that fit the right image,
//! `min_disp..=min(max_disp, x)`, so the left edge of the map stays usable; pixels with
//! `x < min_disp` are invalid. Rows are complete (the census clamps at the image edges).
//!
//! Arithmetic: per-path `L` values are u8 with saturating adds (valid values stay
//! `<= COST_MAX + P2 <= 127`, which is why `P2 <= 79`); `S` is u16. Disparities a pixel cannot have
//! (`x - d < 0`, and the lanes that pad the range to a multiple of 32) get cost 255; their `L`
//! then stays `>= 255 - 127 = 128`, above every valid value, so they never win a minimum.
//!
//! SIMD: AVX2 kernels (`core::arch`, chosen at run time with `is_x86_feature_detected!`) work
//! on 32 disparities per register; the portable kernels compute exactly the same integers, so
//! both give bit-identical maps ([`SgmMatcher::with_simd`] forces the portable path, written
//! so that the compiler vectorises it with baseline SSE2). Costs: the census strings are
//! split into six 4-bit planes; 32 costs are six `pshufb` lookups into popcount tables chosen
//! by the left pixel's nibbles (the right image is census-transformed mirrored, so that a
//! pixel's disparities are consecutive bytes). The minima of the horizontal paths use
//! `_mm_minpos_epu16`; those of the vertical and diagonal paths are reduced eight pixels at a
//! time after each row by a transposing tree of unpacks; S is widened with `unpack` and
//! `maddubs`; the winner and uniqueness tests use compares and `movemask` bit sets, so a
//! pixel needs no data-dependent branch; the block average uses `pmulhuw` for its scaling.
//! All buffers are reused across calls: after the first frame of a size, nothing is
//! allocated.

use hvs_shared::config::StereoConfig;
use hvs_shared::messages::StereoAlgorithm;

use crate::census::{census, census_with};
use crate::equalize::equalize_right;
use crate::post::{lr_check, speckle_filter};
use crate::{
    ImageView, MatchStats, StereoError, StereoMatcher, bad_parameter, check_fits, check_pair,
    check_range, check_uniqueness,
};

/// Census window width and height (5x5: 24 comparisons, costs 0..=24).
pub const CENSUS_WINDOW: usize = 5;
/// Largest matching cost: twice the mean census Hamming distance over the block.
pub const COST_MAX: u32 = 2 * CMAX;
/// Largest `P2` accepted: per-path costs (`<= COST_MAX + P2`) must stay below 128 to fit the
/// u8 arithmetic.
pub const MAX_P2: u32 = 127 - COST_MAX;
/// Block sides accepted for the cost averaging.
pub const BLOCK_SIZES: [u32; 4] = [1, 3, 5, 7];

/// Largest census cost (bits of a 5x5 census string).
const CMAX: u32 = (CENSUS_WINDOW * CENSUS_WINDOW - 1) as u32;
// Valid per-path costs (<= COST_MAX + P2) must stay below the smallest value a missing
// disparity can take (255 - (COST_MAX + P2)), and two of them must add up without saturating.
const _: () = assert!(COST_MAX + MAX_P2 <= 127);
/// Disparities per SIMD register (u8 lanes of AVX2).
const LANES: usize = 32;
/// Nibble planes of a 24-bit census string.
const NIBBLES: usize = 6;
/// Cost of a disparity that does not exist for a pixel.
const INVALID_COST: u8 = 255;

/// Semi-global matching parameters (the stereo config plus what it has no field for).
#[derive(Debug, Clone, PartialEq)]
pub struct SgmParams {
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px (inclusive, at most 255).
    pub max_disp: u32,
    /// Penalty for a 1 px disparity change between neighbours (census cost units).
    pub p1: u32,
    /// Penalty for larger changes (`p1 <= p2 <= MAX_P2`).
    pub p2: u32,
    /// Aggregation paths: 4, 5 or 8.
    pub paths: u32,
    /// Side of the block the census costs are averaged over (1, 3, 5 or 7).
    pub block: u32,
    /// Apply the reference equalisation to the right image first.
    pub equalize: bool,
    /// Smooth both images with a 3x3 box before the census transform (robustness to noise
    /// and to a vertical misalignment of about a pixel; see the module notes).
    pub prefilter: bool,
    /// A match is rejected unless its S is this many percent below every S more than one
    /// disparity away (0 disables; below 100).
    pub uniqueness_pct: u32,
    /// Left-right consistency check.
    pub lr_check: bool,
    /// Allowed left-right disagreement, px.
    pub lr_max_diff_px: u32,
    /// Subpixel fit on S (equiangular; see the module notes).
    pub subpixel: bool,
    /// Speckle filter: regions of at most this many pixels are removed (0 disables).
    pub speckle_window_px: u32,
    /// Neighbours within this many px belong to the same speckle region.
    pub speckle_range_px: u32,
    /// Fill invalid runs up to this long from the background side (0 = off).
    pub fill_invalid_px: u32,
    /// Minimum mean |horizontal gradient| of the left image over the texture window, grey
    /// levels per pixel; flatter pixels come out invalid (0 disables).
    pub texture_threshold: f32,
    /// Radius of the (square) texture window.
    pub texture_radius: u32,
}

impl SgmParams {
    /// The parameters a stereo config section describes (texture settings get their defaults).
    pub fn from_config(config: &StereoConfig) -> Self {
        Self {
            min_disp: config.min_disp,
            max_disp: config.max_disp,
            p1: config.sgm.p1,
            p2: config.sgm.p2,
            paths: config.sgm.paths,
            block: config.sgm.block,
            equalize: config.equalize,
            prefilter: true,
            uniqueness_pct: config.uniqueness_pct,
            lr_check: config.lr_check,
            lr_max_diff_px: config.lr_max_diff_px,
            subpixel: config.subpixel,
            speckle_window_px: config.speckle_window_px,
            speckle_range_px: config.speckle_range_px,
            fill_invalid_px: config.fill_invalid_px,
            texture_threshold: config.sgm.texture_threshold,
            texture_radius: config.sgm.texture_radius,
        }
    }

    /// Checks the parameters on their own (image size is checked per call).
    pub fn validate(&self) -> Result<(), StereoError> {
        check_range(self.min_disp, self.max_disp)?;
        if self.max_disp > 255 {
            return bad_parameter(
                "max_disp",
                format!("= {} must be at most 255 for sgm", self.max_disp),
            );
        }
        if !matches!(self.paths, 4 | 5 | 8) {
            return bad_parameter("sgm.paths", format!("= {} must be 4, 5 or 8", self.paths));
        }
        if !BLOCK_SIZES.contains(&self.block) {
            return bad_parameter(
                "sgm.block",
                format!("= {} must be 1, 3, 5 or 7", self.block),
            );
        }
        if self.p2 > MAX_P2 || self.p1 > self.p2 {
            return bad_parameter(
                "sgm.p2",
                format!(
                    "penalties p1 = {}, p2 = {} need p1 <= p2 <= {MAX_P2} (path costs fit a byte)",
                    self.p1, self.p2
                ),
            );
        }
        check_uniqueness(self.uniqueness_pct)?;
        if !(0.0..=64.0).contains(&self.texture_threshold) {
            return bad_parameter(
                "sgm.texture_threshold",
                format!("= {} must be in 0..=64 grey levels", self.texture_threshold),
            );
        }
        if self.texture_radius > 15 {
            return bad_parameter(
                "sgm.texture_radius",
                format!("= {} must be at most 15", self.texture_radius),
            );
        }
        Ok(())
    }
}

/// Image and disparity-range geometry of one call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Geometry {
    width: usize,
    height: usize,
    dmin: usize,
    /// Number of disparities.
    nd: usize,
    /// `nd` rounded up to a multiple of [`LANES`].
    dpad: usize,
}

impl Geometry {
    /// Disparity lanes that exist at column `x` (`x >= dmin`).
    #[inline]
    fn nvalid(&self, x: usize) -> usize {
        (x + 1 - self.dmin).min(self.nd)
    }

    /// Length of one nibble plane (room for reads up to `dpad` lanes past the image).
    fn plane_len(&self) -> usize {
        self.width + self.dpad + LANES
    }
}

/// A zeroed byte buffer whose data starts on a 64-byte boundary, with `GUARD` spare bytes
/// before and after (for the unaligned d±1 loads).
#[derive(Debug, Default)]
struct Aligned {
    buf: Vec<u8>,
    start: usize,
    len: usize,
}

const GUARD: usize = 64;

impl Aligned {
    fn resize(&mut self, len: usize) {
        if self.len != len || self.buf.is_empty() {
            self.buf = vec![0; len + 2 * GUARD + 64];
            let off = self.buf.as_ptr().align_offset(64);
            self.start = off + GUARD;
            self.len = len;
        }
    }

    /// The data including the guards: `[GUARD bytes][len bytes][GUARD bytes]`.
    fn with_guards(&mut self) -> &mut [u8] {
        &mut self.buf[self.start - GUARD..self.start + self.len + GUARD]
    }

    fn data(&self) -> &[u8] {
        &self.buf[self.start..self.start + self.len]
    }

    fn data_mut(&mut self) -> &mut [u8] {
        &mut self.buf[self.start..self.start + self.len]
    }
}

/// The winner of one pixel.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Winner {
    /// Lane (disparity - min_disp) with the lowest S.
    best: u16,
    /// Its S.
    cost: u16,
    /// S one disparity below (`u16::MAX` when that disparity does not exist).
    below: u16,
    /// S one disparity above (`u16::MAX` when that disparity does not exist).
    above: u16,
    /// Passed the uniqueness test.
    unique: bool,
}

/// The winners of one row, one array per field (so that the per-row post-processing
/// vectorises).
#[derive(Debug, Default)]
struct Winners {
    best: Vec<u16>,
    cost: Vec<u16>,
    below: Vec<u16>,
    above: Vec<u16>,
    unique: Vec<u8>,
}

impl Winners {
    fn resize(&mut self, w: usize) {
        for v in [
            &mut self.best,
            &mut self.cost,
            &mut self.below,
            &mut self.above,
        ] {
            v.resize(w, 0);
        }
        self.unique.resize(w, 0);
    }

    #[inline]
    fn set(&mut self, x: usize, win: Winner) {
        self.best[x] = win.best;
        self.cost[x] = win.cost;
        self.below[x] = win.below;
        self.above[x] = win.above;
        self.unique[x] = u8::from(win.unique);
    }
}

/// Scratch buffers, reused across calls.
#[derive(Debug, Default)]
struct Scratch {
    geo: Geometry,
    /// Confidence of the last map, one byte a pixel ([`confidence_row`]).
    confidence: Vec<u8>,
    right_eq: Vec<u8>,
    left_f: Vec<u8>,
    right_f: Vec<u8>,
    mirrored: Vec<u8>,
    row_sum: Vec<u16>,
    grad: Vec<u8>,
    /// Census strings of both images (of the mirrored images for the AVX2 kernels).
    census_l: Vec<u32>,
    census_r: Vec<u32>,
    texture_ok: Vec<u8>,
    col_sum: Vec<u32>,
    prefix: Vec<u32>,
    /// Nibble planes of the (mirrored) right census row, then the "outside the image" plane.
    planes: Aligned,
    /// Costs of one row, `width * dpad`.
    cost: Aligned,
    /// Horizontal block sums of the raw census costs of the last `block + 1` rows
    /// (`width * dpad` each; row `k` in slot `k % (block + 1)`), for the block average.
    ring: Vec<u8>,
    /// The row held by each slot of `ring` (`usize::MAX`: none).
    ring_rows: Vec<usize>,
    /// Block sums: the ring's horizontal sums added over the block's rows, `width * dpad`.
    vsum: Vec<u16>,
    /// Raw census costs of one row before [`row_sums`], `width * dpad`.
    raw: Vec<u8>,
    /// The ← path of one row, `width * dpad`.
    lbuf: Aligned,
    /// S of a block of `PICK_BLOCK` pixels (AVX2 kernels), `dpad` u16 each.
    srow: Aligned,
    /// The vertical and the two diagonal paths of the previous row, slots `x + 1` for
    /// `x = -1..=width` of `dpad` bytes each.
    vbuf: [Aligned; 3],
    /// The minimum of each slot of `vbuf`.
    vmin: [Vec<u8>; 3],
    /// Scalar kernel temporaries (`dpad` each).
    tmp: [Vec<u8>; 6],
    tmp16: Vec<u16>,
    /// S of the top-down sweep for 4 and 8 paths, `width * height * dpad`.
    volume: Vec<u16>,
    winners: Winners,
    /// Uniqueness thresholds by best S (see `RowCfg::uniq_t`) and the percentage they are for.
    uniq_t: Vec<u16>,
    uniq_t_for: Option<u32>,
    left_int: Vec<u16>,
    right_q8: Vec<u16>,
    right_cost: Vec<u16>,
    labels: Vec<u32>,
    stack: Vec<u32>,
}

/// Census + semi-global matcher with reusable scratch buffers.
#[derive(Debug)]
pub struct SgmMatcher {
    params: SgmParams,
    simd: bool,
    scratch: Scratch,
}

/// Whether this CPU can run the AVX2 kernels.
pub fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

impl SgmMatcher {
    /// Builds the matcher from a config section.
    pub fn from_config(config: &StereoConfig) -> Result<Self, StereoError> {
        Self::new(SgmParams::from_config(config))
    }

    /// Creates a matcher; fails on bad parameters. Uses AVX2 when the CPU has it.
    pub fn new(params: SgmParams) -> Result<Self, StereoError> {
        params.validate()?;
        Ok(Self {
            params,
            simd: simd_available(),
            scratch: Scratch::default(),
        })
    }

    /// Allows (`true`, the default) or forbids (`false`: scalar kernels) the AVX2 kernels;
    /// without AVX2 on the CPU the scalar kernels run either way. Results are identical.
    pub fn with_simd(mut self, simd: bool) -> Self {
        self.simd = simd && simd_available();
        self
    }

    /// Sets the texture threshold (mean |horizontal gradient|, grey levels; 0 disables) and
    /// window radius.
    pub fn with_texture(mut self, threshold: f32, radius: u32) -> Result<Self, StereoError> {
        let mut params = self.params.clone();
        params.texture_threshold = threshold;
        params.texture_radius = radius;
        params.validate()?;
        self.params = params;
        Ok(self)
    }

    /// Whether the AVX2 kernels run.
    pub fn uses_simd(&self) -> bool {
        self.simd
    }

    /// The parameters in use.
    pub fn params(&self) -> &SgmParams {
        &self.params
    }

    /// Sizes the scratch buffers for a geometry (no allocation when it is unchanged).
    fn prepare(&mut self, geo: Geometry) {
        let s = &mut self.scratch;
        let n = geo.width * geo.height;
        let changed = s.geo != geo;
        s.geo = geo;
        s.right_eq.resize(n, 0);
        s.confidence.resize(n, 0);
        s.left_f.resize(n, 0);
        s.right_f.resize(n, 0);
        s.mirrored.resize(n, 0);
        s.row_sum.resize(geo.width, 0);
        s.grad.resize(geo.width, 0);
        s.census_l.resize(n, 0);
        s.census_r.resize(n, 0);
        s.texture_ok.resize(n, 1);
        s.col_sum.resize(geo.width, 0);
        s.prefix.resize(geo.width + 1, 0);
        let pl = geo.plane_len();
        s.planes.resize(pl * (NIBBLES + 1));
        if changed {
            // The outside plane: 0 for right pixels inside the image, 255 past its left edge.
            let outside = &mut s.planes.data_mut()[NIBBLES * pl..];
            for (j, v) in outside.iter_mut().enumerate() {
                *v = if j < geo.width { 0 } else { INVALID_COST };
            }
        }
        s.cost.resize(geo.width * geo.dpad);
        let slots = self.params.block as usize + 1;
        s.ring.resize(slots * geo.width * geo.dpad, 0);
        s.ring_rows.resize(slots, usize::MAX);
        s.vsum.resize(geo.width * geo.dpad, 0);
        s.raw.resize(geo.width * geo.dpad, 0);
        s.lbuf.resize(geo.width * geo.dpad);
        s.srow.resize(PICK_BLOCK * geo.dpad * 2);
        for (b, m) in s.vbuf.iter_mut().zip(s.vmin.iter_mut()) {
            b.resize((geo.width + 2) * geo.dpad);
            m.resize(geo.width + 2, 0);
        }
        for t in s.tmp.iter_mut() {
            t.resize(geo.dpad, 0);
        }
        s.tmp16.resize(geo.dpad, 0);
        if self.params.paths != 5 {
            s.volume.resize(n * geo.dpad, 0);
        }
        s.winners.resize(geo.width);
        let u = self.params.uniqueness_pct;
        if s.uniq_t_for != Some(u) {
            s.uniq_t.resize(UNIQ_TABLE, 0);
            for (m, t) in s.uniq_t.iter_mut().enumerate() {
                *t = if u == 0 {
                    0
                } else {
                    ((m as u32 * 100).div_ceil(100 - u)).min(i16::MAX as u32) as u16
                };
            }
            s.uniq_t_for = Some(u);
        }
        s.left_int.resize(geo.width, 0);
        s.right_q8.resize(geo.width, 0);
        s.right_cost.resize(geo.width, 0);
    }
}

impl StereoMatcher for SgmMatcher {
    fn algorithm(&self) -> StereoAlgorithm {
        StereoAlgorithm::Sgm
    }

    fn compute(
        &mut self,
        left: ImageView<'_>,
        right: ImageView<'_>,
        out_q8: &mut [u16],
    ) -> Result<MatchStats, StereoError> {
        check_pair(&left, &right, out_q8.len())?;
        let p = self.params.clone();
        let (w, h) = (left.width, left.height);
        check_fits(&left, p.max_disp, CENSUS_WINDOW as u32)?;
        let nd = (p.max_disp - p.min_disp + 1) as usize;
        let geo = Geometry {
            width: w,
            height: h,
            dmin: p.min_disp as usize,
            nd,
            dpad: nd.div_ceil(LANES) * LANES,
        };
        self.prepare(geo);
        let simd = self.simd;
        let s = &mut self.scratch;

        if p.equalize {
            equalize_right(left.data, right.data, &mut s.right_eq);
        }
        #[cfg(target_arch = "x86_64")]
        if simd {
            // SAFETY: `simd` is only true when AVX2 was detected (`with_simd`, `new`).
            unsafe { front_end_avx2(s, &p, left.data, right.data, w, h) };
        } else {
            front_end(s, &p, left.data, right.data, w, h, false);
        }
        #[cfg(not(target_arch = "x86_64"))]
        front_end(s, &p, left.data, right.data, w, h, false);

        let pen = Penalties {
            p1: p.p1 as u8,
            p2: p.p2 as u8,
        };
        match p.paths {
            5 => sweep(s, &p, pen, simd, false, true, true, Volume::None, out_q8),
            4 | 8 => {
                let diag = p.paths == 8;
                sweep(s, &p, pen, simd, false, true, diag, Volume::Store, out_q8);
                sweep(
                    s,
                    &p,
                    pen,
                    simd,
                    true,
                    false,
                    diag,
                    Volume::AddAndPick,
                    out_q8,
                );
            }
            _ => unreachable!("paths validated"),
        }
        // Columns left of min_disp have no disparity to search.
        for row in out_q8.chunks_exact_mut(w) {
            row[..geo.dmin].fill(0);
        }
        if p.speckle_window_px > 0 {
            speckle_filter(
                out_q8,
                w,
                h,
                p.speckle_window_px as usize,
                p.speckle_range_px,
                &mut s.labels,
                &mut s.stack,
            );
        }
        // Pixels the speckle filter removed (and the columns without a search) have none.
        for (c, &d) in s.confidence.iter_mut().zip(out_q8.iter()) {
            if d == 0 {
                *c = 0;
            }
        }
        if p.fill_invalid_px > 0 {
            // Runs touching the border (the columns left of min_disp) stay empty.
            crate::post::fill_from_background(out_q8, w, p.fill_invalid_px as usize);
            // A filled pixel has no match of its own: the lowest confidence, which fusion
            // leaves out of the ranges and the obstacle scan.
            for (c, &d) in s.confidence.iter_mut().zip(out_q8.iter()) {
                if d != 0 && *c == 0 {
                    *c = FILLED_CONFIDENCE;
                }
            }
        }
        let valid = out_q8.iter().filter(|&&d| d != 0).count();
        Ok(MatchStats {
            valid_px: valid as u32,
            row_align: None,
        })
    }

    fn confidence(&self) -> Option<&[u8]> {
        Some(&self.scratch.confidence)
    }
}

/// Equalised right image (when configured), prefilter, census strings and texture mask.
/// Inlined into the AVX2 copy below so that its plain loops vectorise with AVX2 as well.
#[inline(always)]
fn front_end(
    s: &mut Scratch,
    p: &SgmParams,
    left: &[u8],
    right: &[u8],
    w: usize,
    h: usize,
    simd: bool,
) {
    let right: &[u8] = if p.equalize { &s.right_eq } else { right };
    let (left_px, right_px): (&[u8], &[u8]) = if p.prefilter {
        box3(left, w, h, &mut s.row_sum, &mut s.left_f);
        box3(right, w, h, &mut s.row_sum, &mut s.right_f);
        (&s.left_f, &s.right_f)
    } else {
        (left, right)
    };
    if simd {
        // The AVX2 kernels read the right census strings of one row in order of decreasing
        // x. Census of the mirrored images gives exactly that order (its strings are those of
        // the original with their bits permuted, which changes no Hamming distance).
        mirror(left_px, w, &mut s.mirrored);
        census(
            &s.mirrored,
            w,
            h,
            CENSUS_WINDOW,
            CENSUS_WINDOW,
            &mut s.census_l,
        );
        mirror(right_px, w, &mut s.mirrored);
        census(
            &s.mirrored,
            w,
            h,
            CENSUS_WINDOW,
            CENSUS_WINDOW,
            &mut s.census_r,
        );
    } else {
        // The portable path: no hand-written SIMD anywhere, the census included.
        census_with(
            left_px,
            w,
            h,
            CENSUS_WINDOW,
            CENSUS_WINDOW,
            &mut s.census_l,
            false,
        );
        census_with(
            right_px,
            w,
            h,
            CENSUS_WINDOW,
            CENSUS_WINDOW,
            &mut s.census_r,
            false,
        );
    }
    if p.texture_threshold > 0.0 {
        texture_mask(
            w,
            h,
            p.texture_radius as usize,
            (p.texture_threshold * 16.0).round() as u32,
            |y, buf| gradient_row(&left_px[y * w..(y + 1) * w], buf),
            &mut s.grad,
            &mut s.col_sum,
            &mut s.prefix,
            &mut s.texture_ok,
        );
    }
}

/// [`front_end`] compiled for AVX2 (same results: integer code only).
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn front_end_avx2(
    s: &mut Scratch,
    p: &SgmParams,
    left: &[u8],
    right: &[u8],
    w: usize,
    h: usize,
) {
    front_end(s, p, left, right, w, h, true);
}

/// 3x3 box mean (`(sum + 4) / 9`, edge pixels repeated) of `src` into `dst`; `row_sum` is
/// scratch of `w` u16.
#[inline(always)]
fn box3(src: &[u8], w: usize, h: usize, row_sum: &mut [u16], dst: &mut [u8]) {
    for y in 0..h {
        let r0 = &src[y.saturating_sub(1) * w..][..w];
        let r1 = &src[y * w..][..w];
        let r2 = &src[(y + 1).min(h - 1) * w..][..w];
        for (((s, &a), &b), &c) in row_sum.iter_mut().zip(r0).zip(r1).zip(r2) {
            *s = a as u16 + b as u16 + c as u16;
        }
        let out = &mut dst[y * w..(y + 1) * w];
        out[0] = ((2 * row_sum[0] + row_sum[1.min(w - 1)] + 4) / 9) as u8;
        out[w - 1] = ((2 * row_sum[w - 1] + row_sum[w.saturating_sub(2)] + 4) / 9) as u8;
        for (o, t) in out[1..w - 1].iter_mut().zip(row_sum.windows(3)) {
            *o = ((t[0] + t[1] + t[2] + 4) / 9) as u8;
        }
    }
}

/// The two SGM penalties as u8.
#[derive(Debug, Clone, Copy)]
struct Penalties {
    p1: u8,
    p2: u8,
}

/// What a sweep does with S.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Volume {
    /// Pick the winners directly (5 paths).
    None,
    /// Store S for a second sweep.
    Store,
    /// Add the stored S, then pick the winners.
    AddAndPick,
}

/// Each row of `src` reversed into `dst`.
#[inline(always)]
fn mirror(src: &[u8], w: usize, dst: &mut [u8]) {
    for (d, s) in dst.chunks_exact_mut(w).zip(src.chunks_exact(w)) {
        for (o, &v) in d.iter_mut().zip(s.iter().rev()) {
            *o = v;
        }
    }
}

/// `grad[x] = |row[x + 1] - row[x - 1]|` (edge pixels repeated).
#[inline(always)]
fn gradient_row(row: &[u8], grad: &mut [u8]) {
    let w = row.len();
    if w < 3 {
        grad.fill(0);
        return;
    }
    grad[0] = row[1].abs_diff(row[0]);
    grad[w - 1] = row[w - 1].abs_diff(row[w - 2]);
    for (g, t) in grad[1..w - 1].iter_mut().zip(row.windows(3)) {
        *g = t[2].abs_diff(t[0]);
    }
}

/// Texture mask: `ok[i] = 1` where the mean of `rows(y)` (the horizontal gradient) over the
/// (border-clipped) `(2r+1)^2` window around pixel `i` is at least `threshold16 / 16`.
/// `rows(y, buf)` writes row `y` of the measured map into `buf`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn texture_mask(
    w: usize,
    h: usize,
    r: usize,
    threshold16: u32,
    mut rows: impl FnMut(usize, &mut [u8]),
    buf: &mut [u8],
    col_sum: &mut [u32],
    prefix: &mut [u32],
    ok: &mut [u8],
) {
    col_sum.fill(0);
    let mut add_row = |y: usize, col_sum: &mut [u32], add: bool| {
        rows(y, buf);
        if add {
            col_sum
                .iter_mut()
                .zip(buf.iter())
                .for_each(|(c, &g)| *c += g as u32);
        } else {
            col_sum
                .iter_mut()
                .zip(buf.iter())
                .for_each(|(c, &g)| *c -= g as u32);
        }
    };
    for y in 0..r.min(h) {
        add_row(y, col_sum, true);
    }
    for y in 0..h {
        if y + r < h {
            add_row(y + r, col_sum, true);
        }
        if y > r {
            add_row(y - r - 1, col_sum, false);
        }
        let rows_in = ((y + r).min(h - 1) + 1 - y.saturating_sub(r)) as u32;
        prefix[0] = 0;
        for x in 0..w {
            prefix[x + 1] = prefix[x] + col_sum[x];
        }
        let out = &mut ok[y * w..(y + 1) * w];
        let test = |sum: u32, area: u32| u8::from(16 * sum >= threshold16 * area);
        // Columns whose window is clipped: 0..r and w - r..w (all of them when w <= 2r).
        for x in (0..r.min(w)).chain(r.max(w.saturating_sub(r))..w) {
            let (lo, hi) = (x.saturating_sub(r), (x + r + 1).min(w));
            out[x] = test(prefix[hi] - prefix[lo], rows_in * (hi - lo) as u32);
        }
        if w > 2 * r {
            // Interior: full windows, a loop that vectorises.
            let area = rows_in * (2 * r + 1) as u32;
            let (starts, ends) = (&prefix[..w - 2 * r], &prefix[2 * r + 1..=w]);
            for ((o, &a), &b) in out[r..w - r].iter_mut().zip(starts).zip(ends) {
                *o = test(b - a, area);
            }
        }
    }
}

/// Computes the block's horizontal sums of the raw census costs of row `k` into its slot of
/// the ring (unless it is there already) and returns the slot. Lanes of disparities a pixel
/// cannot have, and the pixels left of `min_disp`, get [`CMAX`]: the block average then
/// counts them as mismatches.
#[inline(always)]
fn raw_row(s: &mut Scratch, k: usize, block: usize, simd: bool) -> usize {
    let geo = s.geo;
    let slots = s.ring_rows.len();
    let slot = k % slots;
    if s.ring_rows[slot] != k {
        let (w, dpad) = (geo.width, geo.dpad);
        let ring = &mut s.ring[slot * w * dpad..(slot + 1) * w * dpad];
        // With a 1-pixel block the raw costs are the sums: straight into the ring.
        let out = if block == 1 { ring } else { &mut s.raw[..] };
        let cl = &s.census_l[k * w..(k + 1) * w];
        let cr = &s.census_r[k * w..(k + 1) * w];
        #[cfg(target_arch = "x86_64")]
        if simd {
            // SAFETY: `simd` is only true when AVX2 was detected (`with_simd`, `new`).
            unsafe {
                avx2::fill_planes(s.planes.data_mut(), geo.plane_len(), cr);
                avx2::raw_costs(&geo, cl, s.planes.data(), out);
            }
        } else {
            scalar::raw_costs(&geo, cl, cr, out);
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = simd;
            scalar::raw_costs(&geo, cl, cr, out);
        }
        if block > 1 {
            let ring = &mut s.ring[slot * w * dpad..(slot + 1) * w * dpad];
            row_sums(&s.raw, geo, block, ring);
        }
        s.ring_rows[slot] = k;
    }
    slot
}

/// `out[x] = sum of raw[x - r ..= x + r]` lane by lane (columns clamped to the image), for
/// `x >= dmin`, in wrapping u8 arithmetic: every sum is at most `block * CMAX <= 168`, so
/// the running sum is exact once its window is complete.
#[inline(always)]
fn row_sums(raw: &[u8], geo: Geometry, block: usize, out: &mut [u8]) {
    let (w, dpad, dmin) = (geo.width, geo.dpad, geo.dmin);
    let r = (block / 2) as isize;
    let col = |x: isize| &raw[(x.clamp(0, w as isize - 1) as usize) * dpad..][..dpad];
    let mut acc = [0u8; 256];
    let acc = &mut acc[..dpad];
    for j in -r..=r {
        for (a, &v) in acc.iter_mut().zip(col(dmin as isize + j)) {
            *a = a.wrapping_add(v);
        }
    }
    out[dmin * dpad..(dmin + 1) * dpad].copy_from_slice(acc);
    for x in dmin + 1..w {
        let (add, sub) = (col(x as isize + r), col(x as isize - 1 - r));
        let o = &mut out[x * dpad..(x + 1) * dpad];
        for (((a, &p), &m), o) in acc.iter_mut().zip(add).zip(sub).zip(o.iter_mut()) {
            *a = a.wrapping_add(p).wrapping_sub(m);
            *o = *a;
        }
    }
}

/// Fills `s.cost` with the costs of row `y`: the census Hamming distances averaged over the
/// `block x block` window (edge rows and columns repeated), scaled to `0..=COST_MAX`
/// (twice the mean, so that half a bit of mean distance still counts), with 255 for the
/// disparities a pixel cannot have. Rows are visited in sweep order (`down` = top-down);
/// the ring holds each row's horizontal sums (u8, [`row_sums`]) and the column sums over
/// the block's rows are updated incrementally (`first`: start of a sweep), in the same pass
/// that scales them into `s.cost`. The sums are separable, so this is the 2D block sum.
///
/// Why the average: the census of a single pixel flips bits under webcam noise and a
/// vertical misalignment; averaging over 5x5 (OpenCV's SGBM sums its pixel costs over
/// `blockSize` windows for the same reason) lowered the mean bad-2 of the three Middlebury
/// scenes with webcam defects from 23.6 to 12.1 % (all filters off, `tests::tune_penalties`),
/// and the clean one from 7.0 to 6.1 %.
#[inline(always)]
fn block_costs(s: &mut Scratch, block: usize, y: usize, down: bool, first: bool, simd: bool) {
    let h = s.geo.height;
    let r = (block / 2) as isize;
    let clamp = |k: isize| k.clamp(0, h as isize - 1) as usize;
    let y = y as isize;
    let dir: isize = if down { 1 } else { -1 };
    let n = (block * block) as u32;
    // floor(h * recip / 2^16) <= COST_MAX for every h <= CMAX * n (see the tests); both
    // factors fit 16 bits for n >= 3, so the product is one `pmulhuw`.
    let recip = (2 * 65536u32).div_ceil(n).min(u16::MAX as u32) as u16;
    // The row to add and the row to take out of the column sums (none at the start of a
    // sweep, whose first rows are added one by one: the same kernel keeps the sums in the
    // lane order it uses).
    let (add_slot, sub_slot) = if first {
        s.ring_rows.fill(usize::MAX);
        s.vsum.fill(0);
        for j in -r..r {
            let slot = raw_row(s, clamp(y + j), block, simd);
            add_row(s, slot, None, recip, block, simd);
        }
        (raw_row(s, clamp(y + r), block, simd), None)
    } else {
        // The row that leaves the window (it is still in the ring), then the new one.
        let sub = raw_row(s, clamp(y - dir - dir * r), block, simd);
        (raw_row(s, clamp(y + dir * r), block, simd), Some(sub))
    };
    add_row(s, add_slot, sub_slot, recip, block, simd);
}

/// Adds ring slot `add` to the column sums and takes slot `sub` out, and writes the scaled
/// sums to `s.cost` (255 in the padding lanes and the disparities past the right image's
/// edge), for the pixels `x >= dmin`.
#[inline(always)]
fn add_row(
    s: &mut Scratch,
    add_slot: usize,
    sub_slot: Option<usize>,
    recip: u16,
    block: usize,
    simd: bool,
) {
    let geo = s.geo;
    let (w, dpad, dmin) = (geo.width, geo.dpad, geo.dmin);
    let len = w * dpad;
    // 255 in the padding lanes (>= nd), which no pixel has.
    let mut pad_mask = [0u8; 256];
    pad_mask[geo.nd..dpad].fill(INVALID_COST);
    let pad_mask = &pad_mask[..dpad];
    let add = &s.ring[add_slot * len..(add_slot + 1) * len];
    let zeros = [0u8; 256];
    let cost = s.cost.data_mut();
    for x in dmin..w {
        let span = x * dpad..(x + 1) * dpad;
        let sub = match sub_slot {
            Some(k) => &s.ring[k * len..(k + 1) * len][span.clone()],
            None => &zeros[..dpad],
        };
        let vsum = &mut s.vsum[span.clone()];
        let out = &mut cost[span.clone()];
        #[cfg(target_arch = "x86_64")]
        if simd {
            // SAFETY: `simd` is only true when AVX2 was detected (`with_simd`, `new`).
            unsafe { avx2::update_and_scale(vsum, &add[span], sub, recip, block, pad_mask, out) };
        } else {
            update_and_scale(vsum, &add[span], sub, recip, block, pad_mask, out);
        }
        #[cfg(not(target_arch = "x86_64"))]
        update_and_scale(vsum, &add[span], sub, recip, block, pad_mask, out);
        let nvalid = geo.nvalid(x);
        if nvalid < geo.nd {
            // Left band: disparities past the right image's edge.
            out[nvalid..].fill(INVALID_COST);
        }
    }
}

/// `sum += add - sub`, then `out = (sum * recip) >> 16 | pad_mask` (`2 * sum` for a
/// 1-pixel block), lane by lane (the AVX2 twin widens and uses one `pmulhuw`).
#[inline(always)]
fn update_and_scale(
    sum: &mut [u16],
    add: &[u8],
    sub: &[u8],
    recip: u16,
    block: usize,
    pad_mask: &[u8],
    out: &mut [u8],
) {
    for ((((v, &a), &m), &p), o) in sum.iter_mut().zip(add).zip(sub).zip(pad_mask).zip(out) {
        *v = v.wrapping_add(a as u16).wrapping_sub(m as u16);
        let c = if block == 1 {
            2 * *v as u32
        } else {
            (*v as u32 * recip as u32) >> 16
        };
        *o = c as u8 | p;
    }
}

/// [`block_costs`] compiled for AVX2 (same results: integer code only).
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn block_costs_avx2(s: &mut Scratch, block: usize, y: usize, down: bool, first: bool) {
    block_costs(s, block, y, down, first, true);
}

/// Runs one sweep over all rows (top-down or bottom-up).
#[allow(clippy::too_many_arguments)]
fn sweep(
    s: &mut Scratch,
    p: &SgmParams,
    pen: Penalties,
    simd: bool,
    bottom_up: bool,
    horiz: bool,
    diag: bool,
    vol: Volume,
    out_q8: &mut [u16],
) {
    let geo = s.geo;
    let (w, h, dpad) = (geo.width, geo.height, geo.dpad);
    for (b, m) in s.vbuf.iter_mut().zip(s.vmin.iter_mut()) {
        b.with_guards().fill(0);
        m.fill(0);
    }
    let block = p.block as usize;
    for step in 0..h {
        let y = if bottom_up { h - 1 - step } else { step };
        #[cfg(target_arch = "x86_64")]
        if simd {
            // SAFETY: `simd` is only true when AVX2 was detected (`with_simd`, `new`).
            unsafe { block_costs_avx2(s, block, y, !bottom_up, step == 0) };
        } else {
            block_costs(s, block, y, !bottom_up, step == 0, false);
        }
        #[cfg(not(target_arch = "x86_64"))]
        block_costs(s, block, y, !bottom_up, step == 0, false);
        let vol_row: &mut [u16] = if vol == Volume::None {
            &mut []
        } else {
            &mut s.volume[y * w * dpad..(y + 1) * w * dpad]
        };
        let [v0, v1, v2] = &mut s.vbuf;
        let [m0, m1, m2] = &mut s.vmin;
        let mut row = RowBufs {
            cost: s.cost.data_mut(),
            lbuf: s.lbuf.data_mut(),
            vbuf: [v0.with_guards(), v1.with_guards(), v2.with_guards()],
            vmin: [m0, m1, m2],
            vol: vol_row,
            srow: s.srow.data_mut(),
            winners: &mut s.winners,
        };
        let cfg = RowCfg {
            geo,
            pen,
            uniq: p.uniqueness_pct,
            uniq_t: &s.uniq_t,
            horiz,
            diag,
            vol,
        };
        #[cfg(target_arch = "x86_64")]
        let done = if simd {
            // SAFETY: `simd` is only true when AVX2 was detected (`with_simd`, `new`).
            unsafe { avx2::row(&cfg, &mut row) };
            true
        } else {
            false
        };
        #[cfg(not(target_arch = "x86_64"))]
        let done = false;
        if !done {
            scalar::row(&cfg, &mut row, &mut s.tmp, &mut s.tmp16);
        }
        if vol != Volume::Store {
            finish_row_any(
                simd,
                p,
                geo,
                &s.winners,
                &s.texture_ok[y * w..(y + 1) * w],
                &mut s.left_int,
                &mut s.right_q8,
                &mut s.right_cost,
                &mut out_q8[y * w..(y + 1) * w],
            );
            confidence_row(
                &s.winners,
                &out_q8[y * w..(y + 1) * w],
                &mut s.confidence[y * w..(y + 1) * w],
            );
        }
    }
}

/// The confidence of each pixel of a finished row, from its cost curve: how far the minimum
/// of S stands below its two neighbours (the curvature measure of Hu & Mordohai), `r = (min
/// of the neighbours - S) / (min of the neighbours + 1)`, mapped to `1 + 254 r / (r + 0.05)`
/// (r = 0.05, the uniqueness test's default margin, gives 128); 128 where no neighbour
/// exists; 0 where the row has no disparity (uniqueness, texture or left-right check).
/// Scalar: it costs one pass over the row and gives the same bytes on every CPU.
fn confidence_row(win: &Winners, out: &[u16], conf: &mut [u8]) {
    let w = out.len();
    let (cost, below, above) = (&win.cost[..w], &win.below[..w], &win.above[..w]);
    // Branch-free so that it vectorises: 1 + 254 r / (r + 0.05) with r = (m - S) / (m + 1)
    // is 1 + 254 (m - S) / ((m - S) + 0.05 (m + 1)), one division.
    for ((((c, &d), &s), &lo), &hi) in conf[..w]
        .iter_mut()
        .zip(out)
        .zip(cost)
        .zip(below)
        .zip(above)
    {
        let m = lo.min(hi);
        let (mf, sf) = (m as f32, s as f32);
        let gap = (mf - sf).max(0.0);
        let v = 1.0 + 254.0 * gap / (gap + 0.05 * (mf + 1.0));
        // + 0.5 then truncation: round half up for these positive values.
        let v = if m == u16::MAX { 128 } else { (v + 0.5) as u8 };
        *c = if d == 0 { 0 } else { v };
    }
}

/// The confidence of a pixel filled from the background side ([`crate::post::fill_from_background`]).
pub const FILLED_CONFIDENCE: u8 = 1;

/// Pixels whose S the AVX2 kernels buffer before picking their winners.
const PICK_BLOCK: usize = 32;

/// Entries of the uniqueness threshold table (S is always below 2048).
const UNIQ_TABLE: usize = 2048;

/// Per-row settings of the kernels.
#[derive(Debug, Clone, Copy)]
struct RowCfg<'a> {
    geo: Geometry,
    pen: Penalties,
    uniq: u32,
    /// `uniq_t[m]`: a lane (far from the best) with `S < uniq_t[m]` makes a pixel whose best
    /// S is `m` ambiguous: `S * (100 - u) < m * 100` ⟺ `S < ceil(m * 100 / (100 - u))`.
    uniq_t: &'a [u16],
    /// Compute the horizontal paths (→ and ←).
    horiz: bool,
    /// Compute the two diagonal paths.
    diag: bool,
    vol: Volume,
}

/// The row buffers the kernels read and write.
struct RowBufs<'a> {
    cost: &'a mut [u8],
    lbuf: &'a mut [u8],
    /// Path buffers with their guards: slot `x + 1` of `x = -1..=width` starts at
    /// `GUARD + (x + 1) * dpad`.
    vbuf: [&'a mut [u8]; 3],
    vmin: [&'a mut [u8]; 3],
    vol: &'a mut [u16],
    /// S of a block of `PICK_BLOCK` pixels (AVX2 kernels), `dpad` u16 each, as bytes.
    srow: &'a mut [u8],
    winners: &'a mut Winners,
}

/// `post::to_q8(d as f32)` for an integer disparity `d <= 255`, without the float rounding
/// or a branch (only d = 0 gives 0, raised to 1 like `to_q8` does).
#[inline]
fn q8_int(d: u16) -> u16 {
    (d << 8).max(1)
}

/// Equiangular ("V") fit through (-1, c_minus), (0, c0), (1, c_plus): the offset in
/// [-0.5, 0.5] where two lines of opposite slope through the points meet (OpenCV's
/// `(p - n) / (p + n - 2 c + |p - n|)`), 0 when the costs are flat. Chosen over
/// [`crate::post::parabola_offset`] because it is measurably better on SGM sums (see the
/// module notes).
#[inline]
fn equiangular_offset(c_minus: f32, c0: f32, c_plus: f32) -> f32 {
    let rise = c_minus.max(c_plus) - c0;
    if rise > 0.0 {
        (0.5 * (c_minus - c_plus) / rise).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// A disparity in px to the 1/256-px encoding of [`crate::post::to_q8`] (`round(256 d)`, at least 1)
/// without a call to the float rounding function; `d >= 0`.
#[inline]
fn q8_fast(d: f32) -> u16 {
    ((d * 256.0 + 0.5) as i32).clamp(1, u16::MAX as i32) as u16
}

/// Uniqueness, left-right check and subpixel fit of one row of winners; writes the row of
/// the output map.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn finish_row(
    p: &SgmParams,
    geo: Geometry,
    win: &Winners,
    texture_ok: &[u8],
    left_int: &mut [u16],
    right_q8: &mut [u16],
    right_cost: &mut [u16],
    out: &mut [u16],
) {
    let (dmin, w) = (geo.dmin, geo.width);
    let (left_int, out) = (&mut left_int[..w], &mut out[..w]);
    let (best, cost) = (&win.best[..w], &win.cost[..w]);
    let (below, above) = (&win.below[..w], &win.above[..w]);
    left_int[..dmin].fill(0);
    // Integer disparities of the unique, textured winners (written without branches so that
    // the loop vectorises).
    let no_texture = p.texture_threshold == 0.0;
    for (((q, &b), &u), &t) in left_int[dmin..]
        .iter_mut()
        .zip(&best[dmin..])
        .zip(&win.unique[dmin..w])
        .zip(&texture_ok[dmin..w])
    {
        let ok = (u != 0) & (no_texture | (t != 0));
        *q = q8_int(dmin as u16 + b) * u16::from(ok);
    }
    if p.lr_check {
        // The right view the cheap way: each left winner claims right pixel x - d when its S
        // is the lowest claim so far.
        right_q8.fill(0);
        right_cost.fill(u16::MAX);
        for x in dmin..w {
            let (q, c) = (left_int[x], cost[x]);
            let xr = x - dmin - best[x] as usize;
            let (rc, rq) = (right_cost[xr], right_q8[xr]);
            let claim = u16::from((q != 0) & (c < rc));
            right_cost[xr] = rc.wrapping_sub(claim.wrapping_mul(rc.wrapping_sub(c)));
            right_q8[xr] = rq.wrapping_sub(claim.wrapping_mul(rq.wrapping_sub(q)));
        }
        lr_check(left_int, right_q8, w, p.lr_max_diff_px);
    }
    if !p.subpixel {
        out.copy_from_slice(left_int);
        return;
    }
    for (x, o) in out.iter_mut().enumerate() {
        let (q, lo, hi) = (left_int[x], below[x], above[x]);
        let off = equiangular_offset(lo as f32, cost[x] as f32, hi as f32);
        let fine = q8_fast((dmin + best[x] as usize) as f32 + off);
        *o = if (q != 0) & (lo != u16::MAX) & (hi != u16::MAX) {
            fine
        } else {
            q
        };
    }
}

/// [`finish_row`], compiled for AVX2 when `simd` (same results: the float code is plain
/// IEEE arithmetic either way).
#[allow(clippy::too_many_arguments)]
fn finish_row_any(
    simd: bool,
    p: &SgmParams,
    geo: Geometry,
    win: &Winners,
    texture_ok: &[u8],
    left_int: &mut [u16],
    right_q8: &mut [u16],
    right_cost: &mut [u16],
    out: &mut [u16],
) {
    /// # Safety
    /// The CPU must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    unsafe fn finish_row_avx2(
        p: &SgmParams,
        geo: Geometry,
        win: &Winners,
        texture_ok: &[u8],
        left_int: &mut [u16],
        right_q8: &mut [u16],
        right_cost: &mut [u16],
        out: &mut [u16],
    ) {
        finish_row(p, geo, win, texture_ok, left_int, right_q8, right_cost, out);
    }
    #[cfg(target_arch = "x86_64")]
    if simd {
        // SAFETY: `simd` is only true when AVX2 was detected (`with_simd`, `new`).
        unsafe { finish_row_avx2(p, geo, win, texture_ok, left_int, right_q8, right_cost, out) };
        return;
    }
    let _ = simd;
    finish_row(p, geo, win, texture_ok, left_int, right_q8, right_cost, out);
}

/// Portable kernels: the same integers as the AVX2 ones, lane by lane.
mod scalar {
    use super::*;

    /// One path step over all `dpad` lanes: `out = C + min(prev, prev±1 + P1, mprev + P2) - mprev`
    /// in saturating u8 arithmetic (lanes past the ends see 255 as their neighbour). Returns
    /// the minimum of `out`. (Written as branch-free slice loops so that the compiler
    /// vectorises them with the baseline SSE2.)
    #[inline]
    pub(super) fn step(prev: &[u8], mprev: u8, cost: &[u8], pen: Penalties, out: &mut [u8]) -> u8 {
        let n = prev.len();
        let cap = mprev.saturating_add(pen.p2);
        let lane = |lm: u8, l0: u8, lp: u8, c: u8| {
            let t = lm.min(lp).saturating_add(pen.p1).min(l0).min(cap);
            c.saturating_add(t).saturating_sub(mprev)
        };
        // n is a multiple of 32.
        out[0] = lane(u8::MAX, prev[0], prev[1], cost[0]);
        out[n - 1] = lane(prev[n - 2], prev[n - 1], u8::MAX, cost[n - 1]);
        for (o, (t, &c)) in out[1..n - 1]
            .iter_mut()
            .zip(prev.windows(3).zip(&cost[1..n - 1]))
        {
            *o = lane(t[0], t[1], t[2], c);
        }
        out.iter().fold(u8::MAX, |m, &v| m.min(v))
    }

    /// Raw costs of one row (`width * dpad`): Hamming distances for the disparities that
    /// exist, [`CMAX`] otherwise (and for every lane of the pixels left of `min_disp`).
    pub(super) fn raw_costs(geo: &Geometry, cl: &[u32], cr: &[u32], out: &mut [u8]) {
        let dpad = geo.dpad;
        out[..geo.dmin * dpad].fill(CMAX as u8);
        for x in geo.dmin..geo.width {
            let out = &mut out[x * dpad..(x + 1) * dpad];
            let nvalid = geo.nvalid(x);
            let c = cl[x];
            // Lane i compares with right pixel x - dmin - i: the right row read backwards.
            let right = &cr[x + 1 - geo.dmin - nvalid..=x - geo.dmin];
            for (o, &r) in out[..nvalid].iter_mut().zip(right.iter().rev()) {
                *o = crate::census::hamming(c, r) as u8;
            }
            out[nvalid..].fill(CMAX as u8);
        }
    }

    /// One row (costs in `b.cost`): ← (right to left), then →, ↓ and the diagonals (left to right),
    /// S, and the winners or the volume.
    pub(super) fn row(
        cfg: &RowCfg<'_>,
        b: &mut RowBufs<'_>,
        tmp: &mut [Vec<u8>; 6],
        s16: &mut [u16],
    ) {
        let geo = cfg.geo;
        let (w, dmin, dpad) = (geo.width, geo.dmin, geo.dpad);
        let [prev_h, cur, held, hold_next, lr, _] = tmp;
        // Right to left: ←.
        prev_h.fill(0);
        let mut mprev = 0u8;
        for x in (dmin..w).rev() {
            let c = &b.cost[x * dpad..(x + 1) * dpad];
            if cfg.horiz {
                let l = &mut b.lbuf[x * dpad..(x + 1) * dpad];
                mprev = step(prev_h, mprev, c, cfg.pen, l);
                prev_h.copy_from_slice(l);
            }
        }
        // Left to right.
        prev_h.fill(0);
        let mut mprev_h = 0u8;
        held.fill(0);
        let mut held_min = 0u8;
        let slot = |x: usize| GUARD + x * dpad; // slot index x (= pixel x - 1)
        for x in dmin..w {
            let s = x + 1;
            let c = &b.cost[x * dpad..(x + 1) * dpad];
            // ↓: in place.
            let m = step(
                &b.vbuf[0][slot(s)..slot(s) + dpad],
                b.vmin[0][s],
                c,
                cfg.pen,
                cur,
            );
            b.vbuf[0][slot(s)..slot(s) + dpad].copy_from_slice(cur);
            b.vmin[0][s] = m;
            // S groups (the AVX2 kernel adds pairs in saturating u8 first, then widens).
            if cfg.diag {
                // From x - 1: read slot s - 1, then store the held result of x - 1 there.
                let m1 = step(
                    &b.vbuf[1][slot(s - 1)..slot(s - 1) + dpad],
                    b.vmin[1][s - 1],
                    c,
                    cfg.pen,
                    hold_next,
                );
                b.vbuf[1][slot(s - 1)..slot(s - 1) + dpad].copy_from_slice(held);
                b.vmin[1][s - 1] = held_min;
                held.copy_from_slice(hold_next);
                held_min = m1;
                // From x + 1: read slot s + 1, write slot s.
                let m2 = step(
                    &b.vbuf[2][slot(s + 1)..slot(s + 1) + dpad],
                    b.vmin[2][s + 1],
                    c,
                    cfg.pen,
                    lr,
                );
                b.vbuf[2][slot(s)..slot(s) + dpad].copy_from_slice(lr);
                b.vmin[2][s] = m2;
            }
            if cfg.horiz {
                let mh = step(prev_h, mprev_h, c, cfg.pen, hold_next);
                prev_h.copy_from_slice(hold_next);
                mprev_h = mh;
            }
            // Sum in the same groups as the AVX2 kernel (pairs added in saturating u8 first).
            let s16 = &mut s16[..dpad];
            let left = &b.lbuf[x * dpad..(x + 1) * dpad];
            let pair = |a: &[u8], b: &[u8], s16: &mut [u16]| {
                for ((o, &u), &v) in s16.iter_mut().zip(a).zip(b) {
                    *o += u.saturating_add(v) as u16;
                }
            };
            let single = |a: &[u8], s16: &mut [u16]| {
                for (o, &u) in s16.iter_mut().zip(a) {
                    *o += u as u16;
                }
            };
            s16.fill(0);
            match (cfg.horiz, cfg.diag) {
                (true, true) => {
                    pair(prev_h, held, s16);
                    pair(cur, lr, s16);
                    single(left, s16);
                }
                (true, false) => {
                    pair(prev_h, cur, s16);
                    single(left, s16);
                }
                (false, true) => {
                    pair(cur, held, s16);
                    single(lr, s16);
                }
                (false, false) => single(cur, s16),
            }
            match cfg.vol {
                Volume::Store => b.vol[x * dpad..(x + 1) * dpad].copy_from_slice(&s16[..dpad]),
                Volume::AddAndPick | Volume::None => {
                    if cfg.vol == Volume::AddAndPick {
                        for (sv, &v) in s16.iter_mut().zip(&b.vol[x * dpad..(x + 1) * dpad]) {
                            *sv += v;
                        }
                    }
                    b.winners
                        .set(x, pick(&s16[..dpad], geo.nvalid(x), cfg.uniq));
                }
            }
        }
        if cfg.diag {
            let s = w + 1;
            b.vbuf[1][slot(s - 1)..slot(s - 1) + dpad].copy_from_slice(held);
            b.vmin[1][s - 1] = held_min;
        }
    }

    /// Winner-take-all over the first `nvalid` lanes of S, with the uniqueness test.
    pub(super) fn pick(s: &[u16], nvalid: usize, uniq: u32) -> Winner {
        let s = &s[..nvalid];
        let min = |v: &[u16]| v.iter().fold(u16::MAX, |m, &x| m.min(x));
        let cost = min(s);
        // The lowest disparity with the lowest S.
        let best = s.iter().position(|&v| v == cost).unwrap_or(0);
        // Ambiguous when some S more than one disparity away satisfies
        // S * (100 - u) < best S * 100; the lowest such S decides.
        let far = min(&s[..best.saturating_sub(1)]).min(min(s.get(best + 2..).unwrap_or(&[])));
        let unique = uniq == 0 || far as u32 * (100 - uniq) >= cost as u32 * 100;
        Winner {
            best: best as u16,
            cost,
            below: if best > 0 { s[best - 1] } else { u16::MAX },
            above: if best + 1 < nvalid {
                s[best + 1]
            } else {
                u16::MAX
            },
            unique,
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::*;
    use core::arch::x86_64::*;

    /// `table[n][r] = popcount(n ^ (r & 15))`, repeated in both 128-bit halves.
    static POPCNT_XOR: [[u8; 32]; 16] = {
        let mut t = [[0u8; 32]; 16];
        let mut n = 0;
        while n < 16 {
            let mut r = 0;
            while r < 32 {
                t[n][r] = ((n ^ (r & 15)) as u32).count_ones() as u8;
                r += 1;
            }
            n += 1;
        }
        t
    };

    /// Lane 0 set to 0xFF.
    static FIRST_LANE: [u8; 32] = {
        let mut t = [0u8; 32];
        t[0] = 0xFF;
        t
    };
    /// Lane 31 set to 0xFF.
    static LAST_LANE: [u8; 32] = {
        let mut t = [0u8; 32];
        t[31] = 0xFF;
        t
    };

    /// Loads 32 bytes (no alignment needed).
    ///
    /// # Safety
    /// `p..p + 32` must be readable; the CPU must have AVX2.
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn ld(p: *const u8) -> __m256i {
        // SAFETY: the caller guarantees 32 readable bytes; loadu has no alignment requirement.
        unsafe { _mm256_loadu_si256(p.cast()) }
    }

    /// Stores 32 bytes (no alignment needed).
    ///
    /// # Safety
    /// `p..p + 32` must be writable; the CPU must have AVX2.
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn st(p: *mut u8, v: __m256i) {
        // SAFETY: the caller guarantees 32 writable bytes; storeu has no alignment requirement.
        unsafe { _mm256_storeu_si256(p.cast(), v) }
    }

    /// Loads a 32-byte array (safe: the array is exactly one register).
    #[target_feature(enable = "avx2")]
    #[inline]
    fn _mm256_loadu_si256_arr(a: &[u8; 32]) -> __m256i {
        // SAFETY: `a` is 32 readable bytes; loadu has no alignment requirement.
        unsafe { _mm256_loadu_si256(a.as_ptr().cast()) }
    }

    /// Minimum of the u8 lanes of `v`, as the low byte (and low u16) of the result.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn hmin_u8<const NV: usize>(v: &[__m256i; NV]) -> __m128i {
        let mut m = v[0];
        for x in v.iter().skip(1) {
            m = _mm256_min_epu8(m, *x);
        }
        let m = _mm_min_epu8(_mm256_castsi256_si128(m), _mm256_extracti128_si256::<1>(m));
        let m = _mm_min_epu8(m, _mm_srli_epi16::<8>(m));
        _mm_minpos_epu16(_mm_and_si128(m, _mm_set1_epi16(0xFF)))
    }

    /// One path step from registers (horizontal paths): the d±1 neighbours come from lane
    /// shifts across the `NV` registers, with 255 shifted in at both ends.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn step_regs<const NV: usize>(
        prev: &[__m256i; NV],
        mprev: __m256i,
        cost: &[__m256i; NV],
        p1: __m256i,
        p2: __m256i,
    ) -> [__m256i; NV] {
        let ones = _mm256_set1_epi8(-1);
        let cap = _mm256_adds_epu8(mprev, p2);
        let mut out = [_mm256_setzero_si256(); NV];
        for k in 0..NV {
            let a = prev[k];
            let before = if k > 0 { prev[k - 1] } else { ones };
            let after = if k + 1 < NV { prev[k + 1] } else { ones };
            // lm[i] = L[i - 1]: [before.hi | a.lo] aligned with a.
            let lm = _mm256_alignr_epi8::<15>(a, _mm256_permute2x128_si256::<0x21>(before, a));
            // lp[i] = L[i + 1]: [a.hi | after.lo] aligned with a.
            let lp = _mm256_alignr_epi8::<1>(_mm256_permute2x128_si256::<0x21>(a, after), a);
            let t = _mm256_adds_epu8(_mm256_min_epu8(lm, lp), p1);
            let t = _mm256_min_epu8(_mm256_min_epu8(t, a), cap);
            out[k] = _mm256_subs_epu8(_mm256_adds_epu8(cost[k], t), mprev);
        }
        out
    }

    /// One path step from a buffer slot (vertical and diagonal paths): the d±1 neighbours are
    /// unaligned loads, with 255 forced into the lanes past the ends.
    ///
    /// # Safety
    /// `prev - 1 .. prev + 32 * NV + 1` must be readable; the CPU must have AVX2.
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn step_mem<const NV: usize>(
        prev: *const u8,
        mprev: u8,
        cost: &[__m256i; NV],
        p1: __m256i,
        p2: __m256i,
    ) -> [__m256i; NV] {
        let mpv = _mm256_set1_epi8(mprev as i8);
        let cap = _mm256_adds_epu8(mpv, p2);
        let first = _mm256_loadu_si256_arr(&FIRST_LANE);
        let last = _mm256_loadu_si256_arr(&LAST_LANE);
        let mut out = [_mm256_setzero_si256(); NV];
        for k in 0..NV {
            let base = prev.wrapping_add(k * LANES);
            // SAFETY: base - 1 .. base + 33 lies in prev - 1 .. prev + 32 * NV + 1, readable by
            // the caller's guarantee.
            let (a, mut lm, mut lp) =
                unsafe { (ld(base), ld(base.wrapping_sub(1)), ld(base.wrapping_add(1))) };
            if k == 0 {
                lm = _mm256_or_si256(lm, first);
            }
            if k + 1 == NV {
                lp = _mm256_or_si256(lp, last);
            }
            let t = _mm256_adds_epu8(_mm256_min_epu8(lm, lp), p1);
            let t = _mm256_min_epu8(_mm256_min_epu8(t, a), cap);
            out[k] = _mm256_subs_epu8(_mm256_adds_epu8(cost[k], t), mpv);
        }
        out
    }

    /// `widen(a) + widen(b)` in fewer instructions: the bytes of `a` and `b` interleaved,
    /// then adjacent pairs added by `maddubs` (at most 255 + 255, no saturation).
    #[target_feature(enable = "avx2")]
    #[inline]
    fn widen_sum(a: __m256i, b: __m256i) -> (__m256i, __m256i) {
        let ones = _mm256_set1_epi8(1);
        (
            _mm256_maddubs_epi16(_mm256_unpacklo_epi8(a, b), ones),
            _mm256_maddubs_epi16(_mm256_unpackhi_epi8(a, b), ones),
        )
    }

    /// Zero-extends the u8 lanes of `v` to two u16 registers: lanes 0..8 and 16..24, then
    /// 8..16 and 24..32 (the in-lane order of `unpack`; `pick_block` undoes it).
    #[target_feature(enable = "avx2")]
    #[inline]
    fn widen(v: __m256i) -> (__m256i, __m256i) {
        let z = _mm256_setzero_si256();
        (_mm256_unpacklo_epi8(v, z), _mm256_unpackhi_epi8(v, z))
    }

    /// Winner-take-all with the uniqueness test for pixels `x0..x1` of a row, from S stored
    /// by `pass2` from the start of `srow` (`2 * NV` u16 registers per pixel, two per block of 32 disparities in the
    /// order `widen` leaves them: the first holds disparities 0..8 and 16..24 of the block,
    /// the second 8..16 and 24..32, so that `packs` of two compare results gives the block's
    /// 32 lanes in order for `movemask`). `uniq_t[m]` is the uniqueness threshold for a best
    /// S of `m` (0: no test).
    #[target_feature(enable = "avx2")]
    #[inline]
    fn pick_block<const NV2: usize>(
        srow: &[u8],
        x0: usize,
        x1: usize,
        geo: Geometry,
        uniq_t: &[u16],
        win: &mut Winners,
    ) {
        // Within this function `dmin..w` is the block `x0..x1`.
        let (w, dmin) = (x1, x0);
        let stride = NV2 * 32;
        let uniq_t: &[u16; UNIQ_TABLE] = match uniq_t.try_into() {
            Ok(t) => t,
            Err(_) => return,
        };
        let rows = srow[..(x1 - x0) * stride].chunks_exact(stride);
        let outs = win.best[dmin..w]
            .iter_mut()
            .zip(&mut win.cost[dmin..w])
            .zip(&mut win.below[dmin..w])
            .zip(&mut win.above[dmin..w])
            .zip(&mut win.unique[dmin..w]);
        for (x, (bytes, ((((best_o, cost_o), below_o), above_o), unique_o))) in
            (dmin..w).zip(rows.zip(outs))
        {
            let nvalid = geo.nvalid(x);
            // SAFETY: bytes holds NV2 registers (chunks of NV2 * 32 bytes).
            let s: [__m256i; NV2] = core::array::from_fn(|q| unsafe {
                _mm256_loadu_si256(bytes.as_ptr().add(32 * q).cast())
            });
            let mut m = s[0];
            for v in s.iter().skip(1) {
                m = _mm256_min_epu16(m, *v);
            }
            let m = _mm_minpos_epu16(_mm_min_epu16(
                _mm256_castsi256_si128(m),
                _mm256_extracti128_si256::<1>(m),
            ));
            let cost = (_mm_cvtsi128_si32(m) & 0x7FF) as u16; // S < 2048
            let mb = _mm256_broadcastw_epi16(m);
            let tv = _mm256_set1_epi16(uniq_t[cost as usize] as i16);
            // Per block of 32 disparities: lanes equal to the minimum, lanes below the threshold.
            let eq_bits = |b: usize| {
                let eq = _mm256_packs_epi16(
                    _mm256_cmpeq_epi16(s[2 * b], mb),
                    _mm256_cmpeq_epi16(s[2 * b + 1], mb),
                );
                _mm256_movemask_epi8(eq) as u32
            };
            let lt_bits = |b: usize| {
                let lt = _mm256_packs_epi16(
                    _mm256_cmpgt_epi16(tv, s[2 * b]),
                    _mm256_cmpgt_epi16(tv, s[2 * b + 1]),
                );
                _mm256_movemask_epi8(lt) as u32
            };
            // Lanes that do not exist hold larger S than every lane that does, so the first
            // lane equal to the minimum is a valid one. A pixel is ambiguous when a lane that
            // exists, more than one disparity away from the best, is below the threshold.
            let (best, unique) = if NV2 <= 4 {
                // Up to 64 disparities: one u64 bit set, no branches.
                let (mut eq, mut lt) = (0u64, 0u64);
                for b in 0..NV2 / 2 {
                    eq |= (eq_bits(b) as u64) << (LANES * b);
                    lt |= (lt_bits(b) as u64) << (LANES * b);
                }
                let best = (eq.trailing_zeros() as usize).min(63);
                let valid = if nvalid >= 64 {
                    u64::MAX
                } else {
                    (1u64 << nvalid) - 1
                };
                let near = if best == 0 { 3 } else { 7u64 << (best - 1) };
                (best, lt & valid & !near == 0)
            } else if NV2 <= 8 {
                // Up to 128 disparities: the same with u128.
                let (mut eq, mut lt) = (0u128, 0u128);
                for b in 0..NV2 / 2 {
                    eq |= (eq_bits(b) as u128) << (LANES * b);
                    lt |= (lt_bits(b) as u128) << (LANES * b);
                }
                let best = (eq.trailing_zeros() as usize).min(127);
                let valid = if nvalid >= 128 {
                    u128::MAX
                } else {
                    (1u128 << nvalid) - 1
                };
                let near = if best == 0 { 3 } else { 7u128 << (best - 1) };
                (best, lt & valid & !near == 0)
            } else {
                let mut best = 0usize;
                for b in (0..NV2 / 2).rev() {
                    let bits = eq_bits(b);
                    if bits != 0 {
                        best = b * LANES + bits.trailing_zeros() as usize;
                    }
                }
                let mut unique = true;
                for b in 0..NV2 / 2 {
                    let far =
                        block_bits(b, 0, nvalid) & !block_bits(b, best.saturating_sub(1), best + 2);
                    unique &= lt_bits(b) & far == 0;
                }
                (best, unique)
            };
            // The neighbours of the winner, for the subpixel fit: best - 1 >= 0 and
            // best + 1 < nvalid <= dpad lie in this pixel's S.
            let lane = |d: usize| {
                let i = 2 * lane_slot(d).min(NV2 * 16 - 1);
                u16::from_le_bytes([bytes[i], bytes[i + 1]])
            };
            *best_o = best as u16;
            *cost_o = cost;
            *below_o = if best > 0 { lane(best - 1) } else { u16::MAX };
            *above_o = if best + 1 < nvalid {
                lane(best + 1)
            } else {
                u16::MAX
            };
            *unique_o = u8::from(unique);
        }
    }

    /// Where disparity lane `d` lies in the u16 registers of S (see `pick_block`).
    #[inline]
    fn lane_slot(d: usize) -> usize {
        let (block, i) = (d / LANES, d % LANES);
        block * LANES + ((i >> 3) & 1) * 16 + (i >> 4) * 8 + (i & 7)
    }

    /// Bits `i` of the 32-lane block `b` with `lo <= 32 b + i < hi`.
    #[inline]
    fn block_bits(b: usize, lo: usize, hi: usize) -> u32 {
        let base = b * LANES;
        let lo = lo.clamp(base, base + LANES) - base;
        let hi = hi.clamp(base, base + LANES) - base;
        let upto = |n: usize| if n >= 32 { u32::MAX } else { (1u32 << n) - 1 };
        upto(hi) & !upto(lo)
    }

    /// Nibble planes of one row of (mirrored) right census strings: plane `j` at index `i`
    /// holds bits `4 j .. 4 j + 4` of `row[i]`, which in mirrored order is right pixel
    /// `w - 1 - i`.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn fill_planes(planes: &mut [u8], plane_len: usize, row: &[u32]) {
        let w = row.len();
        assert!(planes.len() >= NIBBLES * plane_len && plane_len >= w);
        let fifteen = _mm256_set1_epi32(15);
        let order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
        let mut x = 0;
        while x + 32 <= w {
            let mut v = [_mm256_setzero_si256(); 4];
            for (k, r) in v.iter_mut().enumerate() {
                // SAFETY: x + 8 k + 8 <= x + 32 <= w = row.len().
                *r = unsafe { _mm256_loadu_si256(row.as_ptr().add(x + 8 * k).cast()) };
            }
            for j in 0..NIBBLES {
                let shift = _mm_cvtsi32_si128(4 * j as i32);
                let t: [__m256i; 4] = core::array::from_fn(|k| {
                    _mm256_and_si256(_mm256_srl_epi32(v[k], shift), fifteen)
                });
                let a = _mm256_packus_epi32(t[0], t[1]);
                let b = _mm256_packus_epi32(t[2], t[3]);
                let bytes = _mm256_permutevar8x32_epi32(_mm256_packus_epi16(a, b), order);
                // SAFETY: j * plane_len + x + 32 <= j * plane_len + w <= planes.len() (asserted).
                unsafe {
                    _mm256_storeu_si256(planes.as_mut_ptr().add(j * plane_len + x).cast(), bytes)
                };
            }
            x += 32;
        }
        for (i, &c) in row.iter().enumerate().skip(x) {
            for j in 0..NIBBLES {
                planes[j * plane_len + i] = ((c >> (4 * j)) & 15) as u8;
            }
        }
    }

    /// One row with `NV` registers of 32 disparities (see `scalar::row`).
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn row(cfg: &RowCfg<'_>, b: &mut RowBufs<'_>) {
        match cfg.geo.dpad / LANES {
            1 => row_nv::<1, 2>(cfg, b),
            2 => row_nv::<2, 4>(cfg, b),
            3 => row_nv::<3, 6>(cfg, b),
            4 => row_nv::<4, 8>(cfg, b),
            5 => row_nv::<5, 10>(cfg, b),
            6 => row_nv::<6, 12>(cfg, b),
            7 => row_nv::<7, 14>(cfg, b),
            8 => row_nv::<8, 16>(cfg, b),
            n => unreachable!("{n} registers: max_disp is at most 255"),
        }
    }

    /// `update_and_scale` with `pmulhuw`: `dpad` lanes, a multiple of 32.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn update_and_scale(
        sum: &mut [u16],
        add: &[u8],
        sub: &[u8],
        recip: u16,
        block: usize,
        pad_mask: &[u8],
        out: &mut [u8],
    ) {
        let n = out.len();
        assert!(n.is_multiple_of(LANES) && sum.len() >= n && pad_mask.len() >= n);
        assert!(add.len() >= n && sub.len() >= n);
        let r = _mm256_set1_epi16(recip as i16);
        let sp = sum.as_mut_ptr().cast::<u8>();
        for i in (0..n).step_by(LANES) {
            // SAFETY: i + 32 <= n, within every slice (asserted; `sum` holds 2n bytes);
            // unaligned loads and stores.
            unsafe {
                let (a0, a1) = widen(ld(add.as_ptr().add(i)));
                let (m0, m1) = widen(ld(sub.as_ptr().add(i)));
                let v0 = _mm256_sub_epi16(_mm256_add_epi16(ld(sp.add(2 * i)), a0), m0);
                let v1 = _mm256_sub_epi16(_mm256_add_epi16(ld(sp.add(2 * i + 32)), a1), m1);
                st(sp.add(2 * i), v0);
                st(sp.add(2 * i + 32), v1);
                let (q0, q1) = if block == 1 {
                    (_mm256_add_epi16(v0, v0), _mm256_add_epi16(v1, v1))
                } else {
                    (_mm256_mulhi_epu16(v0, r), _mm256_mulhi_epu16(v1, r))
                };
                // Every cost is at most COST_MAX: no saturation in the pack, which puts the
                // lanes `widen` interleaved back in order (the sums stay interleaved).
                let q = _mm256_packus_epi16(q0, q1);
                let m = ld(pad_mask.as_ptr().add(i));
                st(out.as_mut_ptr().add(i), _mm256_or_si256(q, m));
            }
        }
    }

    /// Raw costs of one row (see `scalar::raw_costs`) from the census strings of the
    /// mirrored left row and the nibble planes of the mirrored right row.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn raw_costs(geo: &Geometry, cl: &[u32], planes: &[u8], out: &mut [u8]) {
        match geo.dpad / LANES {
            1 => raw_costs_nv::<1>(geo, cl, planes, out),
            2 => raw_costs_nv::<2>(geo, cl, planes, out),
            3 => raw_costs_nv::<3>(geo, cl, planes, out),
            4 => raw_costs_nv::<4>(geo, cl, planes, out),
            5 => raw_costs_nv::<5>(geo, cl, planes, out),
            6 => raw_costs_nv::<6>(geo, cl, planes, out),
            7 => raw_costs_nv::<7>(geo, cl, planes, out),
            8 => raw_costs_nv::<8>(geo, cl, planes, out),
            n => unreachable!("{n} registers: max_disp is at most 255"),
        }
    }

    #[target_feature(enable = "avx2")]
    fn raw_costs_nv<const NV: usize>(geo: &Geometry, cl: &[u32], planes: &[u8], out: &mut [u8]) {
        let (w, dmin, dpad, nd) = (geo.width, geo.dmin, geo.dpad, geo.nd);
        let pl = geo.plane_len();
        // The bounds every raw access below relies on.
        assert!(dpad == NV * LANES && cl.len() == w && dmin < w);
        assert!(planes.len() >= (NIBBLES + 1) * pl && out.len() >= w * dpad);
        out[..dmin * dpad].fill(CMAX as u8);
        // Lanes >= nd are padding: force their cost to 255 (then CMAX, like the others).
        let mut pad_bytes = [0u8; 32];
        for (i, v) in pad_bytes.iter_mut().enumerate() {
            if (NV - 1) * LANES + i >= nd {
                *v = 0xFF;
            }
        }
        let pad = _mm256_loadu_si256_arr(&pad_bytes);
        let cmax = _mm256_set1_epi8(CMAX as i8);
        let pptr = planes.as_ptr();
        let optr = out.as_mut_ptr();
        for x in dmin..w {
            // The census rows are mirrored.
            let c = cl[w - 1 - x];
            let mut tabs = [_mm256_setzero_si256(); NIBBLES];
            for (j, t) in tabs.iter_mut().enumerate() {
                let n = ((c >> (4 * j)) & 15) as usize;
                *t = _mm256_loadu_si256_arr(&POPCNT_XOR[n]);
            }
            // Reversed-plane index of right pixel x - dmin (lane 0).
            let base = w - 1 - x + dmin;
            for k in 0..NV {
                let off = base + k * LANES;
                // SAFETY: off + 32 <= w - 1 + dpad < pl, so every plane load stays inside
                // `planes` ((NIBBLES + 1) * pl bytes, asserted); x * dpad + k * 32 + 32 <=
                // w * dpad <= out.len() (asserted).
                unsafe {
                    let mut sum = _mm256_shuffle_epi8(tabs[0], ld(pptr.wrapping_add(off)));
                    for (j, t) in tabs.iter().enumerate().skip(1) {
                        sum = _mm256_add_epi8(
                            sum,
                            _mm256_shuffle_epi8(*t, ld(pptr.wrapping_add(j * pl + off))),
                        );
                    }
                    // The outside plane adds 255 to the disparities past the image's edge.
                    sum = _mm256_adds_epu8(sum, ld(pptr.wrapping_add(NIBBLES * pl + off)));
                    if k + 1 == NV {
                        sum = _mm256_or_si256(sum, pad);
                    }
                    st(
                        optr.wrapping_add(x * dpad + k * LANES),
                        _mm256_min_epu8(sum, cmax),
                    );
                }
            }
        }
    }

    #[target_feature(enable = "avx2")]
    fn row_nv<const NV: usize, const NV2: usize>(cfg: &RowCfg<'_>, b: &mut RowBufs<'_>) {
        let geo = cfg.geo;
        let (w, dmin, dpad) = (geo.width, geo.dmin, geo.dpad);
        // The bounds every raw access below relies on.
        assert!(dpad == NV * LANES && NV2 == 2 * NV && dmin < w);
        assert!(b.cost.len() >= w * dpad && b.lbuf.len() >= w * dpad);
        for v in b.vbuf.iter() {
            assert!(v.len() >= (w + 2) * dpad + 2 * GUARD);
        }
        for m in b.vmin.iter() {
            assert!(m.len() >= w + 2);
        }
        assert!(cfg.vol == Volume::None || b.vol.len() >= w * dpad);
        assert!(b.winners.best.len() >= w && b.srow.len() >= PICK_BLOCK * 2 * dpad);

        let p1 = _mm256_set1_epi8(cfg.pen.p1 as i8);
        let p2 = _mm256_set1_epi8(cfg.pen.p2 as i8);
        let cost_ptr = b.cost.as_mut_ptr();
        let lbuf_ptr = b.lbuf.as_mut_ptr();

        if cfg.horiz {
            pass1::<NV>(cfg, p1, p2, cost_ptr, lbuf_ptr);
        }
        pass2::<NV, NV2>(cfg, b, p1, p2, cost_ptr, lbuf_ptr);
    }

    /// Right to left: the ← path (bounds asserted by `row_nv`).
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    fn pass1<const NV: usize>(
        cfg: &RowCfg<'_>,
        p1: __m256i,
        p2: __m256i,
        cost_ptr: *mut u8,
        lbuf_ptr: *mut u8,
    ) {
        let geo = cfg.geo;
        let (w, dmin, dpad) = (geo.width, geo.dmin, geo.dpad);
        let mut prev = [_mm256_setzero_si256(); NV];
        let mut mprev = _mm256_setzero_si256();
        for x in (dmin..w).rev() {
            let mut cost = [_mm256_setzero_si256(); NV];
            for (k, cv) in cost.iter_mut().enumerate() {
                // SAFETY: x * dpad + k * 32 + 32 <= w * dpad <= cost.len() (asserted).
                *cv = unsafe { ld(cost_ptr.wrapping_add(x * dpad + k * LANES)) };
            }
            let l = step_regs(&prev, mprev, &cost, p1, p2);
            for (k, v) in l.iter().enumerate() {
                // SAFETY: x * dpad + k * 32 + 32 <= w * dpad <= lbuf.len() (asserted).
                unsafe { st(lbuf_ptr.wrapping_add(x * dpad + k * LANES), *v) };
            }
            mprev = _mm256_broadcastb_epi8(hmin_u8(&l));
            prev = l;
        }
    }

    /// Left to right: ↓, the diagonals, →, S and the winners (bounds asserted by `row_nv`).
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    fn pass2<const NV: usize, const NV2: usize>(
        cfg: &RowCfg<'_>,
        b: &mut RowBufs<'_>,
        p1: __m256i,
        p2: __m256i,
        cost_ptr: *mut u8,
        lbuf_ptr: *mut u8,
    ) {
        let geo = cfg.geo;
        let (w, dmin, dpad) = (geo.width, geo.dmin, geo.dpad);
        // Left to right: ↓, the diagonals, →, S, winners.
        let [vb0, vb1, vb2] = &mut b.vbuf;
        let (v0, v1, v2) = (vb0.as_mut_ptr(), vb1.as_mut_ptr(), vb2.as_mut_ptr());
        let [m0, m1, m2] = &mut b.vmin;
        // Slot s (pixel s - 1) of a path buffer; slots 0..=w + 1 with GUARD bytes either side.
        let slot = |s: usize| GUARD + s * dpad;
        let mut prev = [_mm256_setzero_si256(); NV];
        let mut mprev = _mm256_setzero_si256();
        let mut held = [_mm256_setzero_si256(); NV];
        for x in dmin..w {
            let s = x + 1;
            let mut cost = [_mm256_setzero_si256(); NV];
            let mut left = [_mm256_setzero_si256(); NV];
            for k in 0..NV {
                // SAFETY: x * dpad + k * 32 + 32 <= w * dpad <= cost.len(), lbuf.len() (asserted).
                unsafe {
                    cost[k] = ld(cost_ptr.wrapping_add(x * dpad + k * LANES));
                    if cfg.horiz {
                        left[k] = ld(lbuf_ptr.wrapping_add(x * dpad + k * LANES));
                    }
                }
            }
            // SAFETY: slots s - 1, s and s + 1 lie in 0..=w + 1; a slot plus one byte either
            // side lies inside the buffer ((w + 2) * dpad + 2 * GUARD bytes, asserted).
            let down = unsafe { step_mem(v0.wrapping_add(slot(s)), m0[s], &cost, p1, p2) };
            for (k, v) in down.iter().enumerate() {
                // SAFETY: as above, slot s is inside the buffer.
                unsafe { st(v0.wrapping_add(slot(s) + k * LANES), *v) };
            }
            let mut sum = [_mm256_setzero_si256(); NV2];
            if cfg.diag {
                // From x - 1: read slot s - 1, then store the held result of x - 1 there.
                // SAFETY: slot s - 1 is inside the buffer (see above).
                let dr =
                    unsafe { step_mem(v1.wrapping_add(slot(s - 1)), m1[s - 1], &cost, p1, p2) };
                for (k, v) in held.iter().enumerate() {
                    // SAFETY: slot s - 1 is inside the buffer.
                    unsafe { st(v1.wrapping_add(slot(s - 1) + k * LANES), *v) };
                }
                held = dr;
                // From x + 1: read slot s + 1, write slot s.
                // SAFETY: slots s and s + 1 are inside the buffer.
                let dl =
                    unsafe { step_mem(v2.wrapping_add(slot(s + 1)), m2[s + 1], &cost, p1, p2) };
                for (k, v) in dl.iter().enumerate() {
                    // SAFETY: slot s is inside the buffer.
                    unsafe { st(v2.wrapping_add(slot(s) + k * LANES), *v) };
                }
                if cfg.horiz {
                    let h = step_regs(&prev, mprev, &cost, p1, p2);
                    mprev = _mm256_broadcastb_epi8(hmin_u8(&h));
                    prev = h;
                    for k in 0..NV {
                        let (ab0, ab1) = widen_sum(
                            _mm256_adds_epu8(h[k], dr[k]),
                            _mm256_adds_epu8(down[k], dl[k]),
                        );
                        let (c0, c1) = widen(left[k]);
                        sum[2 * k] = _mm256_add_epi16(ab0, c0);
                        sum[2 * k + 1] = _mm256_add_epi16(ab1, c1);
                    }
                } else {
                    for k in 0..NV {
                        let (a0, a1) = widen(_mm256_adds_epu8(down[k], dr[k]));
                        let (b0, b1) = widen(dl[k]);
                        sum[2 * k] = _mm256_add_epi16(a0, b0);
                        sum[2 * k + 1] = _mm256_add_epi16(a1, b1);
                    }
                }
            } else if cfg.horiz {
                let h = step_regs(&prev, mprev, &cost, p1, p2);
                mprev = _mm256_broadcastb_epi8(hmin_u8(&h));
                prev = h;
                for k in 0..NV {
                    let (a0, a1) = widen(_mm256_adds_epu8(h[k], down[k]));
                    let (c0, c1) = widen(left[k]);
                    sum[2 * k] = _mm256_add_epi16(a0, c0);
                    sum[2 * k + 1] = _mm256_add_epi16(a1, c1);
                }
            } else {
                for k in 0..NV {
                    let (a0, a1) = widen(down[k]);
                    sum[2 * k] = a0;
                    sum[2 * k + 1] = a1;
                }
            }
            match cfg.vol {
                Volume::Store => {
                    let vp = b.vol.as_mut_ptr().wrapping_add(x * dpad).cast::<u8>();
                    for (k, v) in sum.iter().enumerate() {
                        // SAFETY: (x + 1) * dpad u16 <= w * dpad <= vol.len() (asserted).
                        unsafe { st(vp.wrapping_add(k * 32), *v) };
                    }
                }
                Volume::AddAndPick | Volume::None => {
                    if cfg.vol == Volume::AddAndPick {
                        let vp = b.vol.as_ptr().wrapping_add(x * dpad).cast::<u8>();
                        for (k, v) in sum.iter_mut().enumerate() {
                            // SAFETY: (x + 1) * dpad u16 <= w * dpad <= vol.len() (asserted).
                            *v = _mm256_add_epi16(*v, unsafe { ld(vp.wrapping_add(k * 32)) });
                        }
                    }
                    // S goes to a small block buffer; the winners of a block are picked in a
                    // loop of their own (independent pixels, S already in L1), not right after
                    // the stores, whose data a scalar load could not yet forward.
                    let i = (x - dmin) % PICK_BLOCK;
                    let dst = &mut b.srow[i * 2 * dpad..(i + 1) * 2 * dpad];
                    for (k, v) in sum.iter().enumerate() {
                        // SAFETY: dst holds 2 * dpad = NV2 * 32 bytes.
                        unsafe { st(dst.as_mut_ptr().add(k * 32), *v) };
                    }
                    if i + 1 == PICK_BLOCK || x + 1 == w {
                        pick_block::<NV2>(
                            b.srow,
                            x + 1 - (i + 1),
                            x + 1,
                            geo,
                            cfg.uniq_t,
                            b.winners,
                        );
                    }
                }
            }
        }
        if cfg.diag {
            for (k, v) in held.iter().enumerate() {
                // SAFETY: slot w is inside the buffer.
                unsafe { st(v1.wrapping_add(slot(w) + k * LANES), *v) };
            }
        }
        // The minima of the new slots, for the next row (all at once: see `slot_mins`).
        // SAFETY: slots 0..w + 2 of dpad bytes each lie inside the buffers (asserted).
        unsafe {
            slot_mins::<NV>(v0.wrapping_add(GUARD), m0);
            if cfg.diag {
                slot_mins::<NV>(v1.wrapping_add(GUARD), m1);
                slot_mins::<NV>(v2.wrapping_add(GUARD), m2);
            }
        }
    }

    /// `mins[i]` = the minimum of the `32 * NV` bytes of slot `i` at `slots + 32 * NV * i`,
    /// for every `i < mins.len()`. Eight slots at a time: their registers are min-reduced
    /// together by a transposing tree of unpacks (about 3 operations a slot instead of 7 for
    /// one `minpos` reduction each).
    ///
    /// # Safety
    /// The CPU must have AVX2; `mins.len()` slots of `32 * NV` bytes must be readable.
    #[target_feature(enable = "avx2")]
    #[inline(never)]
    unsafe fn slot_mins<const NV: usize>(slots: *const u8, mins: &mut [u8]) {
        let stride = NV * LANES;
        let reduce = |i: usize| {
            let p = slots.wrapping_add(i * stride);
            // SAFETY: slot i < mins.len() is readable (the caller's guarantee).
            let mut m = unsafe { ld(p) };
            for k in 1..NV {
                // SAFETY: as above.
                m = _mm256_min_epu8(m, unsafe { ld(p.wrapping_add(k * LANES)) });
            }
            m
        };
        let n = mins.len();
        let mut i = 0;
        while i + 8 <= n {
            let v: [__m256i; 8] = core::array::from_fn(|j| reduce(i + j));
            // Bytes of slot pairs interleaved, then 16-bit groups of four slots, then 32-bit
            // groups of eight; every step halves the partial minima per slot.
            let t: [__m256i; 4] = core::array::from_fn(|j| {
                let (a, b) = (v[2 * j], v[2 * j + 1]);
                _mm256_min_epu8(_mm256_unpacklo_epi8(a, b), _mm256_unpackhi_epi8(a, b))
            });
            let u0 = _mm256_min_epu8(
                _mm256_unpacklo_epi16(t[0], t[1]),
                _mm256_unpackhi_epi16(t[0], t[1]),
            );
            let u1 = _mm256_min_epu8(
                _mm256_unpacklo_epi16(t[2], t[3]),
                _mm256_unpackhi_epi16(t[2], t[3]),
            );
            let x = _mm256_min_epu8(_mm256_unpacklo_epi32(u0, u1), _mm256_unpackhi_epi32(u0, u1));
            let x = _mm256_min_epu8(x, _mm256_shuffle_epi32::<0x4E>(x));
            let x = _mm256_min_epu8(x, _mm256_permute2x128_si256::<0x01>(x, x));
            let bytes = _mm_cvtsi128_si64(_mm256_castsi256_si128(x)).to_le_bytes();
            mins[i..i + 8].copy_from_slice(&bytes);
            i += 8;
        }
        for (j, m) in mins.iter_mut().enumerate().skip(i) {
            *m = _mm_cvtsi128_si32(hmin_u8(&[reduce(j)])) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{SyntheticPair, degrade, flatten_region, plane, score};

    use hvs_shared::config::SgmConfig;

    fn config(min_disp: u32, max_disp: u32) -> StereoConfig {
        StereoConfig {
            algorithm: StereoAlgorithm::Sgm,
            min_disp,
            max_disp,
            ..StereoConfig::default()
        }
    }

    fn run(m: &mut SgmMatcher, pair: &SyntheticPair) -> Vec<u16> {
        let (w, h) = (pair.width, pair.height);
        let mut out = vec![0u16; w * h];
        let l = ImageView::new(&pair.left, w, h).expect("left");
        let r = ImageView::new(&pair.right, w, h).expect("right");
        m.compute(l, r, &mut out).expect("compute");
        out
    }

    #[test]
    fn confidence_is_zero_exactly_where_there_is_no_disparity() {
        let (w, h) = (160, 120);
        let mut pair = webcam(plane(w, h, 0.0, 0.0, 20.0, 4), 4);
        // An untextured band: no disparity, no confidence.
        crate::synthetic::flatten_region(&mut pair, 90, 130, 128);
        let mut m = SgmMatcher::from_config(&config(4, 40)).expect("cfg");
        let out = run(&mut m, &pair);
        let conf = m.confidence().expect("sgm has a confidence").to_vec();
        assert_eq!(conf.len(), w * h);
        for (i, (&d, &c)) in out.iter().zip(&conf).enumerate() {
            assert_eq!(d == 0, c == 0, "pixel {i}: disparity {d} confidence {c}");
        }
        let valid: Vec<u64> = out
            .iter()
            .zip(&conf)
            .filter(|(d, _)| **d != 0)
            .map(|(_, &c)| c as u64)
            .collect();
        let mean_valid = valid.iter().sum::<u64>() as f64 / valid.len().max(1) as f64;
        assert!(valid.len() > 10_000 && mean_valid > 64.0, "{mean_valid:.1}");
    }

    /// On the real scenes beside the repository, matches within 1 px of the ground truth
    /// carry a higher mean confidence than the ones off by more than 2 px.
    #[test]
    fn confidence_ranks_right_matches_above_wrong_ones_on_real_pairs() {
        let root =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/datasets");
        let Ok(dirs) = crate::eval::list_scenes(&root) else {
            eprintln!("SKIPPED: no datasets at {}", root.display());
            return;
        };
        for dir in dirs {
            let scene = crate::eval::load_scene(&dir).expect("scene");
            let mut m =
                SgmMatcher::from_config(&scene.config(&StereoConfig::default())).expect("cfg");
            let (w, h) = (scene.width, scene.height);
            let mut out = vec![0u16; w * h];
            let l = ImageView::new(&scene.left, w, h).expect("left");
            let r = ImageView::new(&scene.right, w, h).expect("right");
            m.compute(l, r, &mut out).expect("compute");
            let conf = m.confidence().expect("confidence");
            let (mut right, mut wrong) = ((0u64, 0u64), (0u64, 0u64));
            for i in 0..w * h {
                let (d, g) = (out[i], scene.gt_q8[i]);
                if d == 0 || g == 0 || !scene.scored[i] {
                    continue;
                }
                let err = (d as f32 - g as f32).abs() / 256.0;
                let acc = if err <= 1.0 {
                    &mut right
                } else if err > 2.0 {
                    &mut wrong
                } else {
                    continue;
                };
                acc.0 += conf[i] as u64;
                acc.1 += 1;
            }
            let mean = |(sum, n): (u64, u64)| sum as f64 / n.max(1) as f64;
            println!(
                "{}: right {} px mean confidence {:.1}; wrong {} px mean {:.1}",
                scene.name,
                right.1,
                mean(right),
                wrong.1,
                mean(wrong)
            );
            assert!(
                wrong.1 >= 100,
                "{}: too few wrong matches to compare",
                scene.name
            );
            assert!(
                mean(right) > mean(wrong) + 10.0,
                "{}: right {:.1} against wrong {:.1}",
                scene.name,
                mean(right),
                mean(wrong)
            );
        }
    }

    fn webcam(mut pair: SyntheticPair, seed: u64) -> SyntheticPair {
        degrade(&mut pair.right, pair.width, 0.8, 10.0, 4.0, 0, seed);
        pair
    }

    fn xorshift(state: &mut u64) -> u64 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        *state
    }

    /// Two textured planes (left part at `d_far`, right part at `d_near`), as a robot sees a
    /// wall with a box in front of it.
    fn two_planes(
        w: usize,
        h: usize,
        split: usize,
        d_far: f32,
        d_near: f32,
        seed: u64,
    ) -> SyntheticPair {
        let far = plane(w, h, 0.0, 0.0, d_far, seed);
        let near = plane(w, h, 0.0, 0.0, d_near, seed ^ 0x77);
        let mut pair = far.clone();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if x >= split {
                    pair.left[i] = near.left[i];
                    pair.disparity_px[i] = near.disparity_px[i];
                }
                // Right pixel x shows the near plane where it is in front: x + d_near >= split.
                if x as f32 + d_near >= split as f32 {
                    pair.right[i] = near.right[i];
                }
            }
        }
        // Far pixels hidden behind the near plane in the right view are occluded.
        for y in 0..h {
            for x in 0..split.min(w) {
                if x as f32 - d_far + d_near >= split as f32 {
                    pair.disparity_px[y * w + x] = f32::NAN;
                }
            }
        }
        pair
    }

    #[test]
    fn block_average_stays_within_the_cost_range() {
        for block in BLOCK_SIZES {
            let n = block * block;
            if block == 1 {
                continue; // doubled, no division
            }
            let recip = (2 * 65536u32).div_ceil(n).min(u16::MAX as u32);
            let top = (CMAX * n * recip) >> 16;
            assert_eq!(top, COST_MAX, "block {block}");
            // The mean is kept to within half a Hamming bit.
            for sum in 0..=CMAX * n {
                let scaled = if block == 1 {
                    2 * sum
                } else {
                    (sum * recip) >> 16
                };
                let exact = 2.0 * sum as f64 / n as f64;
                assert!(
                    (scaled as f64 - exact).abs() < 1.0,
                    "block {block} sum {sum}"
                );
            }
        }
    }

    #[test]
    fn simd_and_scalar_give_identical_maps() {
        if !simd_available() {
            eprintln!("no AVX2: only the scalar kernels exist here");
            return;
        }
        let mut seed = 0x5EED_1234_u64;
        let cases: &[(usize, usize, u32, u32)] = &[
            (64, 20, 0, 15),
            (90, 17, 3, 40),
            (120, 24, 9, 55),
            (160, 30, 0, 31),
            (161, 21, 5, 37),
            (200, 12, 18, 110),
            (300, 9, 1, 130),
            (100, 8, 20, 21),
            (24, 6, 0, 12),
            (40, 5, 3, 34),
        ];
        for &(w, h, dmin, dmax) in cases {
            // Random noise, a smooth slanted plane and a degraded copy.
            let noise: Vec<u8> = (0..2 * w * h)
                .map(|_| (xorshift(&mut seed) % 256) as u8)
                .collect();
            let mut pairs = vec![SyntheticPair {
                width: w,
                height: h,
                left: noise[..w * h].to_vec(),
                right: noise[w * h..].to_vec(),
                disparity_px: vec![f32::NAN; w * h],
            }];
            let mid = (dmin + dmax) as f32 / 2.0;
            pairs.push(plane(w, h, -0.05, 0.1, mid, seed));
            pairs.push(webcam(plane(w, h, 0.0, 0.0, mid, seed), seed));
            for pair in &pairs {
                for (combo, (paths, uniq)) in [4, 5, 8]
                    .into_iter()
                    .flat_map(|p| [(p, 0), (p, 15)])
                    .enumerate()
                {
                    {
                        let mut cfg = config(dmin, dmax);
                        cfg.sgm.paths = paths;
                        cfg.sgm.block = BLOCK_SIZES[(combo + w) % BLOCK_SIZES.len()];
                        cfg.uniqueness_pct = uniq;
                        cfg.sgm.p1 = 3 + paths;
                        cfg.sgm.p2 = 20 + 3 * uniq;
                        let mut fast = SgmMatcher::from_config(&cfg).expect("cfg").with_simd(true);
                        let mut slow = SgmMatcher::from_config(&cfg).expect("cfg").with_simd(false);
                        assert!(fast.uses_simd() && !slow.uses_simd());
                        let a = run(&mut fast, pair);
                        let b = run(&mut slow, pair);
                        let diff = a.iter().zip(&b).filter(|(x, y)| x != y).count();
                        assert_eq!(
                            diff, 0,
                            "{w}x{h} d {dmin}..={dmax} paths {paths} uniq {uniq} block {}",
                            cfg.sgm.block
                        );
                        // The confidence planes are the same bytes too.
                        assert_eq!(
                            fast.confidence(),
                            slow.confidence(),
                            "confidence {w}x{h} d {dmin}..={dmax} paths {paths}"
                        );
                        // Buffers are reused: a second call gives the same map.
                        assert_eq!(run(&mut fast, pair), a);
                    }
                }
            }
        }
    }

    /// Plain winner-take-all on the census cost, searching the disparities that fit.
    fn census_wta(pair: &SyntheticPair, dmin: usize, dmax: usize) -> Vec<u16> {
        let (w, h) = (pair.width, pair.height);
        let (mut cl, mut cr) = (vec![0; w * h], vec![0; w * h]);
        census(&pair.left, w, h, 5, 5, &mut cl);
        census(&pair.right, w, h, 5, 5, &mut cr);
        let mut out = vec![0u16; w * h];
        for y in 0..h {
            for x in dmin..w {
                let i = y * w + x;
                let mut best = (u32::MAX, 0);
                for d in dmin..=dmax.min(x) {
                    let c = crate::census::hamming(cl[i], cr[i - d]);
                    if c < best.0 {
                        best = (c, d);
                    }
                }
                out[i] = crate::post::to_q8(best.1 as f32);
            }
        }
        out
    }

    #[test]
    fn zero_penalties_give_plain_census_wta() {
        for (w, h, dmin, dmax, seed) in [
            (80, 20, 4, 30, 1u64),
            (128, 16, 0, 40, 2),
            (70, 11, 9, 55, 3),
        ] {
            let pair = webcam(
                plane(w, h, -0.1, 0.05, (dmin + dmax) as f32 / 2.0, seed),
                seed,
            );
            let expected = census_wta(&pair, dmin as usize, dmax as usize);
            for paths in [4, 5, 8] {
                for simd in [false, true] {
                    let mut cfg = config(dmin, dmax);
                    cfg.sgm = hvs_shared::config::SgmConfig {
                        p1: 0,
                        p2: 0,
                        paths,
                        block: 1,
                        ..Default::default()
                    };
                    cfg.uniqueness_pct = 0;
                    cfg.lr_check = false;
                    cfg.subpixel = false;
                    cfg.speckle_window_px = 0;
                    let params = SgmParams {
                        prefilter: false,
                        texture_threshold: 0.0,
                        ..SgmParams::from_config(&cfg)
                    };
                    let mut m = SgmMatcher::new(params).expect("params").with_simd(simd);
                    let out = run(&mut m, &pair);
                    let diff = out.iter().zip(&expected).filter(|(a, b)| a != b).count();
                    assert_eq!(diff, 0, "paths {paths} simd {simd}");
                }
            }
        }
    }

    /// Shares (within 1 px, given a disparity) of the pixels of a synthetic pair that are
    /// visible in the right image with a disparity inside the searched range 9..=55.
    fn accuracy(pair: &SyntheticPair, paths: u32, penalties: (u32, u32)) -> (f32, f32) {
        let mut cfg = config(9, 55);
        cfg.sgm = hvs_shared::config::SgmConfig {
            p1: penalties.0,
            p2: penalties.1,
            paths,
            ..Default::default()
        };
        let mut m = SgmMatcher::from_config(&cfg).expect("cfg");
        let out = run(&mut m, pair);
        let mut in_range = pair.clone();
        for d in in_range.disparity_px.iter_mut() {
            if !(9.0..=55.0).contains(d) {
                *d = f32::NAN;
            }
        }
        score(&in_range, &out, 1.0, 0)
    }

    #[test]
    fn planes_are_recovered_with_and_without_webcam_defects() {
        let (w, h) = (320, 240);
        let scenes = [
            ("fronto-parallel", plane(w, h, 0.0, 0.0, 30.0, 11)),
            ("hallway wall a=-0.2", plane(w, h, -0.2, 0.0, 54.0, 12)),
            ("floor tilt b=0.12", plane(w, h, 0.0, 0.12, 12.0, 13)),
        ];
        for (name, pair) in scenes {
            for (label, p) in [
                ("clean", pair.clone()),
                ("webcam", webcam(pair.clone(), 99)),
            ] {
                // The config default penalties and the recommended ones.
                for (paths, pen) in [(5, (4, 32)), (4, (4, 32)), (8, (4, 32)), (5, (16, 48))] {
                    let (good, dense) = accuracy(&p, paths, pen);
                    eprintln!(
                        "{name} {label} paths {paths} {pen:?}: good {good:.3} dense {dense:.3}"
                    );
                    assert!(
                        good >= 0.95,
                        "{name} {label} paths {paths} {pen:?}: good {good}"
                    );
                    assert!(
                        dense >= 0.95,
                        "{name} {label} paths {paths} {pen:?}: dense {dense}"
                    );
                }
            }
        }
    }

    #[test]
    fn flat_block_between_two_planes_is_invalid() {
        let (w, h) = (240, 80);
        let split = 120;
        let (x0, x1) = (96, 150);
        // (webcam defects on the right, noise sigma on the left, texture threshold): a clean
        // flat block and a nearly flat one with the default threshold, and a noisy one with
        // the threshold docs/stereo.md gives for noisy cameras.
        let default_threshold = SgmConfig::default().texture_threshold;
        for (degraded, left_sigma, threshold) in [
            (false, 0.0, default_threshold),
            (true, 0.5, default_threshold),
            (true, 2.0, 1.0),
        ] {
            let mut pair = two_planes(w, h, split, 20.0, 34.0, 21);
            flatten_region(&mut pair, x0, x1, 128);
            if degraded {
                pair = webcam(pair, 5);
                degrade(&mut pair.left, w, 1.0, 0.0, left_sigma, 0, 6);
            }
            // The config default penalties and others.
            for (paths, p1, p2) in [
                (5, 16, 64),
                (4, 16, 64),
                (8, 16, 64),
                (5, 4, 32),
                (5, 8, 79),
            ] {
                let mut cfg = config(9, 55);
                cfg.sgm = SgmConfig {
                    p1,
                    p2,
                    paths,
                    texture_threshold: threshold,
                    ..Default::default()
                };
                let mut m = SgmMatcher::from_config(&cfg).expect("cfg");
                let out = run(&mut m, &pair);
                // Margin: census radius + prefilter radius + texture radius + 1.
                let margin = 2 + 1 + cfg.sgm.texture_radius as usize + 1;
                let inside = (0..h)
                    .flat_map(|y| (x0 + margin..x1 - margin).map(move |x| y * w + x))
                    .collect::<Vec<_>>();
                let valid = inside.iter().filter(|&&i| out[i] != 0).count();
                eprintln!(
                    "degraded {degraded} sigma {left_sigma} paths {paths} P {p1}/{p2}: {valid} of {} valid in the flat block",
                    inside.len()
                );
                assert!(
                    valid * 100 <= inside.len(),
                    "{valid} of {} valid",
                    inside.len()
                );
                // The textured parts around it are still matched.
                let outside: Vec<usize> = (0..h)
                    .flat_map(|y| {
                        (60..x0 - margin)
                            .chain(x1 + margin..w)
                            .map(move |x| y * w + x)
                    })
                    .filter(|&i| pair.disparity_px[i].is_finite())
                    .collect();
                let good = outside
                    .iter()
                    .filter(|&&i| {
                        out[i] != 0 && (out[i] as f32 / 256.0 - pair.disparity_px[i]).abs() <= 1.0
                    })
                    .count();
                assert!(
                    good * 100 >= outside.len() * 85,
                    "{good} of {} good outside",
                    outside.len()
                );
            }
        }
    }

    /// Timing loop for profilers: `SGM_SIZE=640 SGM_ITERS=50 cargo test --release ...
    /// sgm::tests::timing_loop -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing_loop() {
        let env = |k: &str, d: usize| {
            std::env::var(k)
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(d)
        };
        // The benchmark's scene: a slanted plane, disparities 12..53 (320x240) or 40..106.
        let (w, h, dmin, dmax, b, c) = if env("SGM_SIZE", 320) == 640 {
            (640, 480, 18, 110, 50.0, 56.0)
        } else {
            (320, 240, 9, 55, 25.0, 28.0)
        };
        let pair = webcam(plane(w, h, -16.0 / w as f32, b / h as f32, c, 7), 8);
        if let Ok(prefix) = std::env::var("SGM_DUMP") {
            // Raw grey images, for timing other matchers on the same pair.
            std::fs::write(format!("{prefix}_{w}x{h}_left.raw"), &pair.left).expect("dump");
            std::fs::write(format!("{prefix}_{w}x{h}_right.raw"), &pair.right).expect("dump");
        }
        let mut cfg = config(dmin, dmax);
        cfg.sgm.paths = env("SGM_PATHS", 5) as u32;
        let mut m = SgmMatcher::from_config(&cfg)
            .expect("cfg")
            .with_simd(env("SGM_SIMD", 1) == 1);
        // CPU time of this thread (utime + stime in clock ticks of 10 ms): a fair measure
        // when other processes share the cores.
        let cpu_ticks = || {
            std::fs::read_to_string("/proc/thread-self/stat")
                .ok()
                .and_then(|t| {
                    // Fields after the name: state, ppid, ..., utime (11), stime (12).
                    let f: Vec<&str> = t.rsplit(')').next()?.split_whitespace().collect();
                    Some(f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?)
                })
                .unwrap_or(0)
        };
        let iters = env("SGM_ITERS", 30);
        let mut out = vec![0u16; w * h];
        let l = ImageView::new(&pair.left, w, h).expect("left");
        let r = ImageView::new(&pair.right, w, h).expect("right");
        m.compute(l, r, &mut out).expect("warm-up");
        let mut times = Vec::new();
        let c0 = cpu_ticks();
        for _ in 0..iters {
            let t = std::time::Instant::now();
            m.compute(l, r, &mut out).expect("compute");
            times.push(t.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(&out);
        }
        let cpu_ms = (cpu_ticks() - c0) as f64 * 10.0 / iters as f64;
        times.sort_by(f64::total_cmp);
        let pct = |q: f64| times[((times.len() - 1) as f64 * q) as usize];
        eprintln!(
            "{w}x{h}: median {:.2} ms, min {:.2} ms (p10 {:.2}, p90 {:.2}), mean thread CPU time {:.2} ms",
            pct(0.5),
            times[0],
            pct(0.1),
            pct(0.9),
            cpu_ms
        );
    }

    #[test]
    #[ignore]
    fn subpixel_accuracy() {
        let (w, h) = (320, 240);
        let scenes = [
            ("wall", plane(w, h, -0.1, 0.0, 40.0, 51)),
            ("floor", plane(w, h, 0.0, 0.1, 12.0, 52)),
            ("front", plane(w, h, 0.0, 0.0, 30.37, 53)),
        ];
        for (name, pair) in scenes {
            for (label, p) in [("clean", pair.clone()), ("webcam", webcam(pair.clone(), 3))] {
                let mut m = SgmMatcher::from_config(&config(9, 55)).expect("cfg");
                let out = run(&mut m, &p);
                let (mut n, mut sum, mut sq) = (0usize, 0f64, 0f64);
                for (i, &q) in out.iter().enumerate() {
                    let t = p.disparity_px[i];
                    if q != 0 && (9.0..=55.0).contains(&t) {
                        let e = (q as f64 / 256.0 - t as f64).abs();
                        if e < 1.0 {
                            n += 1;
                            sum += e;
                            sq += e * e;
                        }
                    }
                }
                eprintln!(
                    "{name} {label}: mean |err| {:.3} px, rms {:.3} px over {n}",
                    sum / n as f64,
                    (sq / n as f64).sqrt()
                );
            }
        }
        if let Some(scene) = load_scene("venus") {
            let mut cfg = config(scene.min_disp, scene.max_disp);
            cfg.sgm.p1 = 16;
            cfg.sgm.p2 = 48;
            let out = run_scene(&scene, &scene.right, &cfg, None);
            let (mut n, mut sum, mut bad05) = (0usize, 0f64, 0usize);
            for ((&q, &gt), &scored) in out.iter().zip(&scene.gt).zip(&scene.mask) {
                if scored && gt > 0.0 && q != 0 {
                    let e = (q as f64 / 256.0 - gt as f64).abs();
                    if e < 2.0 {
                        n += 1;
                        sum += e;
                        bad05 += usize::from(e > 0.5);
                    }
                }
            }
            eprintln!(
                "venus: mean |err| {:.3} px, bad-0.5 among good {:.1} %",
                sum / n as f64,
                100.0 * bad05 as f64 / n as f64
            );
        }
    }

    /// The config of the ignored sweeps: 9..55 with `SGM_P1`/`SGM_P2` from the environment.
    fn sweep_config() -> StereoConfig {
        let mut cfg = config(9, 55);
        let env = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<u32>().ok());
        cfg.sgm.p1 = env("SGM_P1").unwrap_or(cfg.sgm.p1);
        cfg.sgm.p2 = env("SGM_P2").unwrap_or(cfg.sgm.p2);
        cfg
    }

    #[test]
    #[ignore]
    fn flat_block_sweep() {
        let (w, h) = (320, 120);
        let (x0, x1) = (100, 200);
        for sigma in [0.0f32, 1.0, 2.0, 3.0] {
            for &(thr, r) in &[
                (0.0f32, 3u32),
                (0.25, 3),
                (0.25, 5),
                (0.3, 5),
                (0.375, 3),
                (0.5, 3),
                (0.625, 3),
                (0.75, 3),
                (1.0, 3),
            ] {
                let mut line = format!("sigma {sigma} thr {thr} r {r}:");
                for d_near in [24.0f32, 34.0] {
                    let mut pair = two_planes(w, h, 150, 20.0, d_near, 21);
                    flatten_region(&mut pair, x0, x1, 128);
                    pair = webcam(pair, 5);
                    degrade(&mut pair.left, w, 1.0, 0.0, sigma, 0, 6);
                    let mut m = SgmMatcher::from_config(&sweep_config())
                        .expect("cfg")
                        .with_texture(thr, r)
                        .expect("t");
                    let out = run(&mut m, &pair);
                    let margin = 2 + r as usize + 1;
                    let inside: Vec<usize> = (0..h)
                        .flat_map(|y| (x0 + margin..x1 - margin).map(move |x| y * w + x))
                        .collect();
                    let valid = inside.iter().filter(|&&i| out[i] != 0).count();
                    let wrong = inside
                        .iter()
                        .filter(|&&i| {
                            out[i] != 0
                                && (out[i] as f32 / 256.0 - pair.disparity_px[i]).abs() > 1.0
                        })
                        .count();
                    line += &format!(
                        " valid {:.1}% wrong {:.1}%",
                        100.0 * valid as f32 / inside.len() as f32,
                        100.0 * wrong as f32 / inside.len() as f32
                    );
                }
                eprintln!("{line}");
            }
        }
    }

    /// Addresses of the main scratch buffers (to see that they are not reallocated).
    fn buffer_addresses(m: &SgmMatcher) -> Vec<usize> {
        let s = &m.scratch;
        vec![
            s.census_l.as_ptr() as usize,
            s.census_r.as_ptr() as usize,
            s.left_f.as_ptr() as usize,
            s.mirrored.as_ptr() as usize,
            s.texture_ok.as_ptr() as usize,
            s.planes.buf.as_ptr() as usize,
            s.cost.buf.as_ptr() as usize,
            s.lbuf.buf.as_ptr() as usize,
            s.srow.buf.as_ptr() as usize,
            s.vbuf[1].buf.as_ptr() as usize,
            s.winners.best.as_ptr() as usize,
            s.volume.as_ptr() as usize,
            s.uniq_t.as_ptr() as usize,
        ]
    }

    #[test]
    fn buffers_are_reused_and_sizes_may_change() {
        let big = webcam(plane(160, 60, -0.05, 0.05, 30.0, 61), 62);
        let small = webcam(plane(100, 30, 0.0, 0.0, 20.0, 63), 64);
        for paths in [5, 8] {
            for simd in [true, false] {
                let mut cfg = config(9, 55);
                cfg.sgm.paths = paths;
                let mut m = SgmMatcher::from_config(&cfg).expect("cfg").with_simd(simd);
                let first = run(&mut m, &big);
                let addresses = buffer_addresses(&m);
                assert_eq!(run(&mut m, &big), first);
                assert_eq!(buffer_addresses(&m), addresses, "paths {paths} simd {simd}");
                // Another size, then back: same results as a fresh matcher.
                let mut fresh = SgmMatcher::from_config(&cfg).expect("cfg").with_simd(simd);
                assert_eq!(run(&mut m, &small), run(&mut fresh, &small));
                assert_eq!(run(&mut m, &big), first);
            }
        }
    }

    #[test]
    fn fast_encodings_match_post_to_q8() {
        for d in 0..=255u16 {
            assert_eq!(q8_int(d), crate::post::to_q8(d as f32), "{d}");
        }
        for i in 0..=255 * 64 {
            let v = i as f32 / 64.0 + 0.003;
            assert_eq!(q8_fast(v), crate::post::to_q8(v), "{v}");
        }
        assert_eq!(equiangular_offset(4.0, 2.0, 4.0), 0.0);
        assert_eq!(equiangular_offset(6.0, 2.0, 4.0), 0.25);
        assert_eq!(equiangular_offset(4.0, 2.0, 6.0), -0.25);
        assert_eq!(equiangular_offset(2.0, 2.0, 2.0), 0.0);
    }

    #[test]
    fn bad_inputs_give_the_right_errors() {
        let cfg = config(9, 55);
        let mut m = SgmMatcher::from_config(&cfg).expect("cfg");
        let img = vec![0u8; 100 * 10];
        let small = vec![0u8; 60 * 10];
        let mut out = vec![0u16; 100 * 10];
        let l = ImageView::new(&img, 100, 10).expect("view");
        let r_small = ImageView::new(&small, 60, 10).expect("view");
        assert!(matches!(
            m.compute(l, r_small, &mut out),
            Err(StereoError::SizeMismatch { .. })
        ));
        assert!(matches!(
            m.compute(l, l, &mut out[..10]),
            Err(StereoError::BufferSize { .. })
        ));
        // Not wider than max_disp + census window.
        let narrow = vec![0u8; 60 * 10];
        let n = ImageView::new(&narrow, 60, 10).expect("view");
        let mut out_n = vec![0u16; 60 * 10];
        assert_eq!(
            m.compute(n, n, &mut out_n),
            Err(StereoError::ImageTooSmall {
                width: 60,
                height: 10,
                max_disp: 55,
                window: 5
            })
        );
        let flat = vec![0u8; 100 * 3];
        let f = ImageView::new(&flat, 100, 3).expect("view");
        let mut out_f = vec![0u16; 300];
        assert!(matches!(
            m.compute(f, f, &mut out_f),
            Err(StereoError::ImageTooSmall { .. })
        ));
        // Ranges and parameters.
        assert_eq!(
            SgmMatcher::from_config(&config(20, 20)).err(),
            Some(StereoError::BadRange { min: 20, max: 20 })
        );
        assert!(matches!(
            SgmMatcher::from_config(&config(30, 10)),
            Err(StereoError::BadRange { .. })
        ));
        assert!(matches!(
            SgmMatcher::from_config(&config(0, 300)),
            Err(StereoError::BadParameter { .. })
        ));
        for (p1, p2, paths) in [(4, 32, 6), (4, 80, 5), (40, 32, 5)] {
            let mut c = config(0, 16);
            c.sgm = hvs_shared::config::SgmConfig {
                p1,
                p2,
                paths,
                ..Default::default()
            };
            assert!(
                matches!(
                    SgmMatcher::from_config(&c),
                    Err(StereoError::BadParameter { .. })
                ),
                "{p1} {p2} {paths}"
            );
        }
        let mut c = config(0, 16);
        c.uniqueness_pct = 100;
        assert!(matches!(
            SgmMatcher::from_config(&c),
            Err(StereoError::BadParameter { .. })
        ));
        assert!(
            SgmMatcher::from_config(&config(0, 16))
                .expect("cfg")
                .with_texture(3.0, 40)
                .is_err()
        );
        // The smallest accepted width works.
        let ok = vec![7u8; 61 * 6];
        let o = ImageView::new(&ok, 61, 6).expect("view");
        let mut out_o = vec![0u16; 61 * 6];
        assert!(m.compute(o, o, &mut out_o).is_ok());
        assert_eq!(m.algorithm(), StereoAlgorithm::Sgm);
    }

    #[test]
    fn left_edge_columns_search_the_disparities_that_fit() {
        let pair = plane(200, 40, 0.0, 0.0, 20.0, 31);
        let mut m = SgmMatcher::from_config(&config(4, 60)).expect("cfg");
        let out = run(&mut m, &pair);
        // Columns 20..60 cannot see d = 60 on the right image but still get d = 20.
        let (mut good, mut total) = (0, 0);
        for y in 3..37 {
            for x in 22..60 {
                total += 1;
                let d = out[y * 200 + x];
                if d != 0 && (d as f32 / 256.0 - 20.0).abs() <= 1.0 {
                    good += 1;
                }
            }
        }
        assert!(good * 100 >= total * 90, "{good} of {total}");
        // Columns left of min_disp are invalid.
        assert!((0..40).all(|y| out[y * 200..y * 200 + 4].iter().all(|&d| d == 0)));
    }

    /// A Middlebury scene: grey pair, ground truth (px, 0 = unknown) and the scoring mask.
    struct Scene {
        name: String,
        width: usize,
        height: usize,
        left: Vec<u8>,
        right: Vec<u8>,
        gt: Vec<f32>,
        mask: Vec<bool>,
        min_disp: u32,
        max_disp: u32,
    }

    fn grey(path: &std::path::Path) -> Option<(Vec<u8>, usize, usize)> {
        let img = image::open(path).ok()?.into_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let data = img
            .pixels()
            .map(|p| {
                (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32).round() as u8
            })
            .collect();
        Some((data, w, h))
    }

    fn load_scene(name: &str) -> Option<Scene> {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/datasets")
            .join(name);
        let dir = if dir.exists() {
            dir
        } else {
            std::path::Path::new("/work/shared/datasets").join(name)
        };
        let toml_text = std::fs::read_to_string(dir.join("scene.toml")).ok()?;
        let t: toml::Table = toml_text.parse().ok()?;
        let min_disp = t.get("min_disp")?.as_integer()? as u32;
        let max_disp = t.get("max_disp")?.as_integer()? as u32;
        let mask_name = t
            .get("nonocc_mask")
            .and_then(|v| v.as_str())
            .filter(|s| !s.is_empty())
            .unwrap_or("all.png");
        let (left, width, height) = grey(&dir.join("left.png"))?;
        let (right, _, _) = grey(&dir.join("right.png"))?;
        let gt: Vec<f32> = image::open(dir.join("gt_disp.png"))
            .ok()?
            .into_luma16()
            .pixels()
            .map(|p| p[0] as f32 / 256.0)
            .collect();
        let mask: Vec<bool> = image::open(dir.join(mask_name))
            .ok()?
            .into_luma8()
            .pixels()
            .map(|p| p[0] == 255)
            .collect();
        (gt.len() == width * height && mask.len() == width * height).then(|| Scene {
            name: name.to_string(),
            width,
            height,
            left,
            right,
            gt,
            mask,
            min_disp,
            max_disp,
        })
    }

    /// bad-2 (invalid or off by more than 2 px, over the scored pixels), the density, and the
    /// error among the valid pixels.
    fn bad2(scene: &Scene, est: &[u16]) -> (f32, f32, f32) {
        let (mut n, mut bad, mut valid, mut valid_bad) = (0usize, 0usize, 0usize, 0usize);
        for ((&gt, &scored), &q) in scene.gt.iter().zip(&scene.mask).zip(est) {
            if !scored || gt == 0.0 {
                continue;
            }
            n += 1;
            match crate::q8_to_px(q) {
                Some(d) => {
                    valid += 1;
                    if (d - gt).abs() > 2.0 {
                        bad += 1;
                        valid_bad += 1;
                    }
                }
                None => bad += 1,
            }
        }
        let n = n.max(1) as f32;
        (
            bad as f32 / n,
            valid as f32 / n,
            valid_bad as f32 / valid.max(1) as f32,
        )
    }

    fn run_scene(
        scene: &Scene,
        right: &[u8],
        cfg: &StereoConfig,
        texture: Option<f32>,
    ) -> Vec<u16> {
        let params = SgmParams {
            prefilter: std::env::var("SGM_PRE").map_or(true, |v| v != "0"),
            ..SgmParams::from_config(cfg)
        };
        let mut m = SgmMatcher::new(params)
            .expect("cfg")
            .with_simd(std::env::var("SGM_SIMD").is_err());
        if let Some(t) = texture {
            let r = std::env::var("SGM_TEXR")
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(SgmConfig::default().texture_radius);
            m = m.with_texture(t, r).expect("texture");
        }
        let mut out = vec![0u16; scene.width * scene.height];
        let l = ImageView::new(&scene.left, scene.width, scene.height).expect("left");
        let r = ImageView::new(right, scene.width, scene.height).expect("right");
        m.compute(l, r, &mut out).expect("compute");
        out
    }

    fn degraded_right(scene: &Scene) -> Vec<u8> {
        let mut r = scene.right.clone();
        let v: Vec<f32> = std::env::var("SGM_DEG")
            .ok()
            .map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
            .filter(|v: &Vec<f32>| v.len() == 4)
            .unwrap_or_else(|| vec![0.8, 10.0, 4.0, 1.0]);
        degrade(&mut r, scene.width, v[0], v[1], v[2], v[3] as usize, 4242);
        r
    }

    #[test]
    fn middlebury_sanity() {
        let scenes: Vec<Scene> = ["tsukuba", "venus", "motorcycle"]
            .iter()
            .filter_map(|n| load_scene(n))
            .collect();
        if scenes.is_empty() {
            eprintln!("no Middlebury scenes found: skipped");
            return;
        }
        for scene in &scenes {
            let mut cfg = config(scene.min_disp, scene.max_disp);
            // The penalties recommended for the config default (see the module notes).
            cfg.sgm.p1 = 16;
            cfg.sgm.p2 = 48;
            // The matches themselves: filled pixels (confidence 1) would count as claims.
            cfg.fill_invalid_px = 0;
            for (label, right) in [
                ("clean", scene.right.clone()),
                ("degraded", degraded_right(scene)),
            ] {
                let out = run_scene(scene, &right, &cfg, None);
                let (b, dense, err) = bad2(scene, &out);
                eprintln!(
                    "{} {label}: bad-2 {:.1} % (density {:.1} %, error among valid {:.1} %)",
                    scene.name,
                    100.0 * b,
                    100.0 * dense,
                    100.0 * err
                );
                // Loose bounds: a regression guard, not a benchmark.
                assert!(err < 0.15, "{} {label}: {err}", scene.name);
                assert!(b < 0.40, "{} {label}: {b}", scene.name);
            }
        }
    }

    /// Penalty sweep on the Middlebury scenes (clean and degraded). Run with
    /// `cargo test --release -p hvs-stereo sgm::tests::tune -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn tune_penalties() {
        let scenes: Vec<Scene> = ["tsukuba", "venus", "motorcycle"]
            .iter()
            .filter_map(|n| load_scene(n))
            .collect();
        let rights: Vec<Vec<u8>> = scenes.iter().map(degraded_right).collect();
        let p2s: Vec<u32> = std::env::var("SGM_P2S")
            .ok()
            .map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
            .unwrap_or_else(|| vec![16, 24, 32, 48, 64, 80, 96]);
        let p1s: Vec<u32> = std::env::var("SGM_P1S")
            .ok()
            .map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
            .unwrap_or_else(|| vec![2, 4, 6, 8, 12]);
        let texture: Option<f32> = std::env::var("SGM_TEXTURE")
            .ok()
            .and_then(|s| s.parse().ok());
        let paths: u32 = std::env::var("SGM_PATHS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(5);
        for &p2 in &p2s {
            for &p1 in &p1s {
                if p1 > p2 {
                    continue;
                }
                let mut line = format!("p1 {p1:3} p2 {p2:3}:");
                let mut total = 0.0;
                for (scene, right) in scenes.iter().zip(&rights) {
                    let mut cfg = config(scene.min_disp, scene.max_disp);
                    cfg.sgm = hvs_shared::config::SgmConfig {
                        p1,
                        p2,
                        paths,
                        ..Default::default()
                    };
                    let env = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<u32>().ok());
                    cfg.uniqueness_pct = env("SGM_UNIQ").unwrap_or(cfg.uniqueness_pct);
                    cfg.lr_check = env("SGM_LR").map_or(cfg.lr_check, |v| v != 0);
                    cfg.speckle_window_px = env("SGM_SPECKLE").unwrap_or(cfg.speckle_window_px);
                    for r in [&scene.right, right] {
                        let out = run_scene(scene, r, &cfg, texture);
                        let (b, dense, err) = bad2(scene, &out);
                        total += b;
                        line += &format!(
                            " {:5.1}/{:4.1}/{:4.1}",
                            100.0 * b,
                            100.0 * dense,
                            100.0 * err
                        );
                    }
                }
                eprintln!(
                    "{line}  mean bad-2 {:.2}",
                    100.0 * total / (2 * scenes.len()) as f32
                );
            }
        }
    }
}
