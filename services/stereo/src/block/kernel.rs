//! The kernel of one stripe: running column and row sums, the winner-take-all with its
//! uniqueness test and subpixel offset, and the right-image map for the left-right check.
//! One generic body, built twice: for the baseline target and, picked at run time, for AVX2.

use super::LANES;
use super::costs::{Acc, Feature, Term, ncc_costs};
use super::params::SubpixelFit;
use super::stripe::{AccBufs, Geometry, Job, Part, Stripe};
use super::wta::{first_index, masked_min, masked_min2, right_update};
use crate::post::to_q8;

/// Runs one stripe with the AVX2 build of the kernel when the CPU has it.
pub(super) fn run_stripe<T: Term, A: Acc>(
    job: &Job<'_, T::F>,
    stripe: &mut Stripe,
    part: Part<'_>,
) {
    #[cfg(target_arch = "x86_64")]
    if job.checks.avx2 {
        // SAFETY: `checks.avx2` is only set when `crate::cpu::avx2_popcnt` found AVX2 and
        // POPCNT on this CPU.
        unsafe { stripe_avx2::<T, A>(job, stripe, part) };
        return;
    }
    stripe_rows::<T, A>(job, stripe, part);
}

/// [`stripe_rows`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
fn stripe_avx2<T: Term, A: Acc>(job: &Job<'_, T::F>, stripe: &mut Stripe, part: Part<'_>) {
    stripe_rows::<T, A>(job, stripe, part);
}

/// Copies `src` reversed into the front of `dst` (the rest is padding).
#[inline(always)]
fn reverse_into<F: Copy>(src: &[F], dst: &mut [F]) {
    for (d, s) in dst.iter_mut().zip(src.iter().rev()) {
        *d = *s;
    }
}

/// A left row and a reversed right row.
type RowPair<'a, F> = (&'a [F], &'a [F]);

/// Adds the terms of one image row to the column sums (`sub = None`), or adds one row and
/// subtracts another. `rev_*` are reversed right rows: `R(x - dmin - k) = rev[w - 1 - x + dmin + k]`.
#[inline(always)]
fn update_columns<T: Term, A: Acc>(
    col: &mut [A],
    g: &Geometry,
    left_new: &[T::F],
    rev_new: &[T::F],
    sub: Option<RowPair<'_, T::F>>,
) {
    let (w, dp, dmin) = (g.w, g.dp, g.dmin);
    // Columns left of dmin are never inside a window with a valid disparity.
    for (x, c) in col.chunks_exact_mut(dp).enumerate().skip(dmin) {
        let m = w - 1 - x + dmin;
        let rn = &rev_new[m..m + dp];
        let ln = left_new[x];
        match sub {
            None => {
                for (c, &r) in c.iter_mut().zip(rn) {
                    *c = c.wadd(T::term(ln, r));
                }
            }
            Some((left_old, rev_old)) => {
                let ro = &rev_old[m..m + dp];
                let lo = left_old[x];
                for ((c, &r), &q) in c.iter_mut().zip(rn).zip(ro) {
                    *c = c.wadd(T::term(ln, r)).wsub(T::term(lo, q));
                }
            }
        }
    }
}

/// The output rows of one stripe.
#[inline(always)]
fn stripe_rows<T: Term, A: Acc>(job: &Job<'_, T::F>, stripe: &mut Stripe, part: Part<'_>) {
    let g = job.geom;
    let Geometry {
        w, r, dmin, nd, dp, ..
    } = g;
    let stride = w + dp;
    let Stripe {
        a16,
        a32,
        f8,
        f32,
        right_sum: rsum,
        right_inv: rinv,
        right_parts,
    } = stripe;
    let AccBufs {
        col,
        row,
        cost,
        masks,
    } = A::pick(a16, a32);
    masks.build(dp);
    let feats = T::F::pick(f8, f32);
    col.clear();
    col.resize(w * dp, A::default());
    row.resize(dp, A::default());
    cost.resize(dp, A::default());
    if job.checks.lr {
        right_parts.clear();
        right_parts.resize(LANES * stride, u32::MAX);
    }
    feats.new.resize(stride, T::F::default());
    feats.old.resize(stride, T::F::default());
    rsum.resize(stride, 0.0);
    rinv.resize(stride, 0.0);

    let Part {
        y0,
        disp,
        offsets,
        right,
    } = part;
    let rows = disp.len() / w;
    fn row_of<F>(img: &[F], w: usize, y: usize) -> &[F] {
        &img[y * w..(y + 1) * w]
    }
    let img_row = |img, y| row_of(img, w, y);
    for yy in y0 - r..=y0 + r {
        reverse_into(img_row(job.right, yy), &mut feats.new);
        update_columns::<T, A>(col, &g, img_row(job.left, yy), &feats.new, None);
    }
    let xs = r + dmin;
    let xe = w - r;
    let checks = job.checks;
    for i in 0..rows {
        let y = y0 + i;
        if i > 0 {
            reverse_into(img_row(job.right, y + r), &mut feats.new);
            reverse_into(img_row(job.right, y - r - 1), &mut feats.old);
            update_columns::<T, A>(
                col,
                &g,
                img_row(job.left, y + r),
                &feats.new,
                Some((img_row(job.left, y - r - 1), &feats.old)),
            );
        }
        if let Some(ncc) = &job.ncc {
            reverse_into(&ncc.right_sum[y * w..(y + 1) * w], rsum);
            reverse_into(&ncc.right_inv[y * w..(y + 1) * w], rinv);
        }
        let disp_row = &mut disp[i * w..(i + 1) * w];
        let off_row = &mut offsets[i * w..(i + 1) * w];
        row.fill(A::default());
        for c in col[(xs - r) * dp..(xs + r + 1) * dp].chunks_exact(dp) {
            for (s, &v) in row.iter_mut().zip(c) {
                *s = s.wadd(v);
            }
        }
        for x in xs..xe {
            if x > xs {
                let add = &col[(x + r) * dp..(x + r + 1) * dp];
                let sub = &col[(x - r - 1) * dp..(x - r) * dp];
                for ((s, &a), &b) in row.iter_mut().zip(add).zip(sub) {
                    *s = s.wadd(a).wsub(b);
                }
            }
            let at = y * w + x;
            let textured = checks.texture.is_none_or(|(t, min)| t[at] >= min);
            let defined = job.ncc.is_none_or(|s| s.left_inv[at] > 0.0);
            let usable = textured && defined;
            if !(usable || checks.lr) {
                continue;
            }
            let n = (x - xs + 1).min(nd);
            let m = w - 1 - x + dmin;
            let costs: &[A] = match &job.ncc {
                Some(s) => {
                    ncc_costs(
                        row,
                        &rsum[m..m + dp],
                        &rinv[m..m + dp],
                        s.area,
                        s.left_sum[at],
                        s.left_inv[at],
                        cost,
                    );
                    cost
                }
                None => row,
            };
            if checks.lr {
                // Consecutive pixels update different parts: an update overlapping the last
                // one shifted by one element would defeat store-to-load forwarding.
                let part = (x % LANES) * stride + m;
                right_update(
                    costs,
                    &masks.index,
                    masks.limit32(n, dp),
                    job.pack_shift,
                    &mut right_parts[part..part + dp],
                );
                if !usable {
                    continue;
                }
            }
            let limit = masks.limit(n, dp);
            let best = masked_min(costs, limit);
            let kb = first_index(costs, limit, best);
            if checks.uniqueness_pct > 0 {
                let second = masked_min2(costs, limit, masks.near(kb, dp));
                if second != A::MAX
                    && best.to_u32() as u64 * 100
                        >= second.to_u32() as u64 * (100 - checks.uniqueness_pct as u64)
                {
                    continue;
                }
            }
            disp_row[x] = (((dmin + kb) * 256) as u16).max(1);
            if checks.fit != SubpixelFit::Off && kb > 0 && kb + 1 < n {
                let off = checks.fit.offset(
                    costs[kb - 1].to_u32() as f32,
                    best.to_u32() as f32,
                    costs[kb + 1].to_u32() as f32,
                );
                off_row[x] = (off * 256.0).round() as i16;
            }
        }
        if checks.lr {
            // Right-image disparities along the diagonals: the minimum over the parts.
            let (first, rest) = right_parts.split_at_mut(stride);
            for part in rest.chunks_exact_mut(stride) {
                for (b, p) in first.iter_mut().zip(part.iter_mut()) {
                    *b = (*b).min(*p);
                    *p = u32::MAX;
                }
            }
            let right_row = &mut right[i * w..(i + 1) * w];
            for (j, b) in first[..w].iter().enumerate() {
                right_row[w - 1 - j] = if *b == u32::MAX {
                    0
                } else {
                    to_q8((dmin + (b & 0xFF) as usize) as f32)
                };
            }
            first.fill(u32::MAX);
        }
    }
}
