//! AVX2 kernels: 32 disparities a register, bit-identical to [`super::scalar`].

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
            let t: [__m256i; 4] =
                core::array::from_fn(|k| _mm256_and_si256(_mm256_srl_epi32(v[k], shift), fifteen));
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
            let dr = unsafe { step_mem(v1.wrapping_add(slot(s - 1)), m1[s - 1], &cost, p1, p2) };
            for (k, v) in held.iter().enumerate() {
                // SAFETY: slot s - 1 is inside the buffer.
                unsafe { st(v1.wrapping_add(slot(s - 1) + k * LANES), *v) };
            }
            held = dr;
            // From x + 1: read slot s + 1, write slot s.
            // SAFETY: slots s and s + 1 are inside the buffer.
            let dl = unsafe { step_mem(v2.wrapping_add(slot(s + 1)), m2[s + 1], &cost, p1, p2) };
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
                    pick_block::<NV2>(b.srow, x + 1 - (i + 1), x + 1, geo, cfg.uniq_t, b.winners);
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
