//! Winner-take-all helpers over a padded disparity row: masked minima, the first index of a
//! value, the right-map update and the sliding-window masks.

use super::LANES;
use super::costs::Acc;

// The WTA helpers run over the whole padded disparity row (a multiple of `LANES`), so that
// they are straight vector code with no scalar remainder; entries that must not count are
// OR-ed with an all-ones mask, which makes them `MAX`. A mask for "the first n entries" is a
// window into `[0; dp] ++ [MAX; dp]` (see [`Masks`]).

/// Lowest of `cost[k] | mask[k]`.
#[inline(always)]
pub(super) fn masked_min<A: Acc>(cost: &[A], mask: &[A]) -> A {
    let mut acc = [A::MAX; LANES];
    for (c, m) in cost.chunks_exact(LANES).zip(mask.chunks_exact(LANES)) {
        for i in 0..LANES {
            acc[i] = acc[i].min(c[i].or(m[i]));
        }
    }
    acc.into_iter().fold(A::MAX, A::min)
}

/// Lowest of `cost[k] | m1[k] | m2[k]`.
#[inline(always)]
pub(super) fn masked_min2<A: Acc>(cost: &[A], m1: &[A], m2: &[A]) -> A {
    let mut acc = [A::MAX; LANES];
    for ((c, a), b) in cost
        .chunks_exact(LANES)
        .zip(m1.chunks_exact(LANES))
        .zip(m2.chunks_exact(LANES))
    {
        for i in 0..LANES {
            acc[i] = acc[i].min(c[i].or(a[i]).or(b[i]));
        }
    }
    acc.into_iter().fold(A::MAX, A::min)
}

/// Index of the first `k` with `cost[k] | mask[k] == value` (0 if none).
#[inline(always)]
pub(super) fn first_index<A: Acc>(cost: &[A], mask: &[A], value: A) -> usize {
    for (j, (c, m)) in cost
        .chunks_exact(LANES)
        .zip(mask.chunks_exact(LANES))
        .enumerate()
    {
        let mut bits = 0u32;
        for i in 0..LANES {
            bits |= u32::from(c[i].or(m[i]) == value) << i;
        }
        if bits != 0 {
            return j * LANES + bits.trailing_zeros() as usize;
        }
    }
    0
}

/// Keeps, for each right pixel on the diagonal of a left pixel, the lowest packed
/// `cost >> shift << 8 | k` so far: the lowest cost and, at ties, the smallest disparity.
/// Entries where `mask` (a `u32` limit mask) is set do not count. A plain minimum: a
/// select-and-store here would become a masked store, which is slow on some CPUs.
#[inline(always)]
pub(super) fn right_update<A: Acc>(
    costs: &[A],
    index: &[u32],
    mask: &[u32],
    shift: u32,
    best: &mut [u32],
) {
    for (((b, &c), &k), &m) in best.iter_mut().zip(costs).zip(index).zip(mask) {
        *b = (*b).min(((c.to_u32() >> shift) << 8) | k | m);
    }
}

/// Sliding-window masks for the WTA over `dp` entries.
#[derive(Debug, Default)]
pub(super) struct Masks<A> {
    /// `[0; dp] ++ [MAX; dp]`: `limit(n)` is 0 for the first `n` entries, `MAX` after.
    limit: Vec<A>,
    /// The same for packed `u32` costs.
    limit32: Vec<u32>,
    /// `MAX` at `dp + 1 ..= dp + 3`, else 0: `near(kb)` is `MAX` at `kb - 1 ..= kb + 1`.
    near: Vec<A>,
    /// `0, 1, 2, ...`: the disparity index of each entry.
    pub(super) index: Vec<u32>,
}

impl<A: Acc> Masks<A> {
    pub(super) fn build(&mut self, dp: usize) {
        self.limit.clear();
        self.limit.resize(dp, A::default());
        self.limit.resize(2 * dp, A::MAX);
        self.limit32.clear();
        self.limit32.resize(dp, 0);
        self.limit32.resize(2 * dp, u32::MAX);
        self.near.clear();
        self.near.resize(2 * dp + 4, A::default());
        self.near[dp + 1..=dp + 3].fill(A::MAX);
        self.index.clear();
        self.index.extend(0..dp as u32);
    }

    #[inline(always)]
    pub(super) fn limit(&self, n: usize, dp: usize) -> &[A] {
        &self.limit[dp - n..2 * dp - n]
    }

    #[inline(always)]
    pub(super) fn limit32(&self, n: usize, dp: usize) -> &[u32] {
        &self.limit32[dp - n..2 * dp - n]
    }

    #[inline(always)]
    pub(super) fn near(&self, kb: usize, dp: usize) -> &[A] {
        &self.near[dp + 2 - kb..2 * dp + 2 - kb]
    }
}
