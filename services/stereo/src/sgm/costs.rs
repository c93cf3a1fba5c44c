//! The matching cost of a row: prefilter, census and texture mask per frame (`front_end`),
//! then the census costs block-averaged over `block x block` (`block_costs`).

use super::*;

/// Equalised right image (when configured), prefilter, census strings and texture mask.
/// Inlined into the AVX2 copy below so that its plain loops vectorise with AVX2 as well.
#[inline(always)]
pub(super) fn front_end(
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
pub(super) unsafe fn front_end_avx2(
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
pub(super) fn box3(src: &[u8], w: usize, h: usize, row_sum: &mut [u16], dst: &mut [u8]) {
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

/// Each row of `src` reversed into `dst`.
#[inline(always)]
pub(super) fn mirror(src: &[u8], w: usize, dst: &mut [u8]) {
    for (d, s) in dst.chunks_exact_mut(w).zip(src.chunks_exact(w)) {
        for (o, &v) in d.iter_mut().zip(s.iter().rev()) {
            *o = v;
        }
    }
}

/// `grad[x] = |row[x + 1] - row[x - 1]|` (edge pixels repeated).
#[inline(always)]
pub(super) fn gradient_row(row: &[u8], grad: &mut [u8]) {
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
pub(super) fn texture_mask(
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
pub(super) fn raw_row(s: &mut Scratch, k: usize, block: usize, simd: bool) -> usize {
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
pub(super) fn row_sums(raw: &[u8], geo: Geometry, block: usize, out: &mut [u8]) {
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
/// scenes with webcam defects from 23.6 to 12.1 % (all filters off, `examples/sgm_sweeps.rs tune-penalties`),
/// and the clean one from 7.0 to 6.1 %.
#[inline(always)]
pub(super) fn block_costs(
    s: &mut Scratch,
    block: usize,
    y: usize,
    down: bool,
    first: bool,
    simd: bool,
) {
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
pub(super) fn add_row(
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
pub(super) fn update_and_scale(
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
pub(super) unsafe fn block_costs_avx2(
    s: &mut Scratch,
    block: usize,
    y: usize,
    down: bool,
    first: bool,
) {
    block_costs(s, block, y, down, first, true);
}
