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
//!    pairs went from 7.0 % to 6.1 % (`examples/sgm_sweeps.rs tune-penalties`);
//!    then a texture mask: mean |L(x+1) - L(x-1)| of the (prefiltered) left image over a
//!    square window below [`SgmParams::texture_threshold`] → invalid. SGM would otherwise
//!    fill flat regions with disparities propagated from their borders. The default (0.25
//!    grey levels per pixel over 11x11) clears flat areas with noise up to sigma 0.5; with
//!    noise sigma 2 on the left image about 30 % of a flat block stays valid, two thirds of
//!    it wrong, unless the threshold is raised to 1.0 (`examples/sgm_sweeps.rs flat-block`), which costs
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
//! SIMD: AVX2 kernels (`core::arch`, chosen at run time by [`crate::cpu`]) work
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

use hvs_runtime::config::StereoConfig;
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

#[cfg(target_arch = "x86_64")]
mod avx2;
mod costs;
mod params;
mod paths;
mod scalar;
#[cfg(test)]
mod tests;

use costs::*;
pub use params::SgmParams;
use paths::*;

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
    crate::cpu::avx2()
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
