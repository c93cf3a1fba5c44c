//! The path sweeps over the rows, the winners and the per-row post-processing (subpixel,
//! left-right claims, confidence).

use super::*;

/// Runs one sweep over all rows (top-down or bottom-up).
#[allow(clippy::too_many_arguments)]
pub(super) fn sweep(
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
pub(super) fn confidence_row(win: &Winners, out: &[u16], conf: &mut [u8]) {
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

/// `post::to_q8(d as f32)` for an integer disparity `d <= 255`, without the float rounding
/// or a branch (only d = 0 gives 0, raised to 1 like `to_q8` does).
#[inline]
pub(super) fn q8_int(d: u16) -> u16 {
    (d << 8).max(1)
}

/// Equiangular ("V") fit through (-1, c_minus), (0, c0), (1, c_plus): the offset in
/// [-0.5, 0.5] where two lines of opposite slope through the points meet (OpenCV's
/// `(p - n) / (p + n - 2 c + |p - n|)`), 0 when the costs are flat. Chosen over
/// [`crate::post::parabola_offset`] because it is measurably better on SGM sums (see the
/// module notes).
#[inline]
pub(super) fn equiangular_offset(c_minus: f32, c0: f32, c_plus: f32) -> f32 {
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
pub(super) fn q8_fast(d: f32) -> u16 {
    ((d * 256.0 + 0.5) as i32).clamp(1, u16::MAX as i32) as u16
}

/// Uniqueness, left-right check and subpixel fit of one row of winners; writes the row of
/// the output map.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn finish_row(
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
pub(super) fn finish_row_any(
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
