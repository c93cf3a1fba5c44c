//! The scratch buffers of one stripe, what a stripe reads and writes, and the split of a
//! frame into horizontal stripes run on parallel threads.

use super::costs::{Acc, Term};
use super::kernel::run_stripe;
use super::params::SubpixelFit;
use super::wta::Masks;

/// Running-sum buffers of one stripe.
#[derive(Debug, Default)]
pub(super) struct AccBufs<A> {
    /// Column sums, `w x dp`, disparity innermost.
    pub(super) col: Vec<A>,
    /// Row (window) sums at the current pixel, `dp`.
    pub(super) row: Vec<A>,
    /// NCC costs at the current pixel, `dp`.
    pub(super) cost: Vec<A>,
    /// WTA masks.
    pub(super) masks: Masks<A>,
}

/// Reversed, padded right rows of one stripe.
#[derive(Debug, Default)]
pub(super) struct FeatBufs<F> {
    pub(super) new: Vec<F>,
    pub(super) old: Vec<F>,
}

/// Scratch of one stripe (one thread).
#[derive(Debug, Default)]
pub(super) struct Stripe {
    pub(super) a16: AccBufs<u16>,
    pub(super) a32: AccBufs<u32>,
    pub(super) f8: FeatBufs<u8>,
    pub(super) f32: FeatBufs<u32>,
    pub(super) right_sum: Vec<f32>,
    pub(super) right_inv: Vec<f32>,
    /// Lowest packed cost `cost << 8 | k` of each right pixel of the current row, indexed
    /// `w - 1 - xr`: `LANES` partial minima (left pixels `x` with `x % LANES == p` go to part
    /// `p`), each `w + dp` long.
    pub(super) right_parts: Vec<u32>,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct Geometry {
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) r: usize,
    pub(super) dmin: usize,
    /// Number of disparities.
    pub(super) nd: usize,
    /// `nd` rounded up to whole chunks.
    pub(super) dp: usize,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct Checks<'a> {
    pub(super) texture: Option<(&'a [i32], i32)>,
    pub(super) uniqueness_pct: u32,
    pub(super) lr: bool,
    pub(super) fit: SubpixelFit,
    pub(super) avx2: bool,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct NccStats<'a> {
    pub(super) area: f32,
    pub(super) left_sum: &'a [f32],
    pub(super) left_inv: &'a [f32],
    pub(super) right_sum: &'a [f32],
    pub(super) right_inv: &'a [f32],
}

/// Everything a stripe reads.
pub(super) struct Job<'a, F> {
    pub(super) geom: Geometry,
    /// Right shift that makes every cost fit 24 bits when packed with its disparity index.
    pub(super) pack_shift: u32,
    pub(super) checks: Checks<'a>,
    pub(super) left: &'a [F],
    pub(super) right: &'a [F],
    pub(super) ncc: Option<NccStats<'a>>,
}

/// Full-image outputs: integer disparity (q8), subpixel offset (1/256 px), right map (q8).
pub(super) struct Outputs<'a> {
    pub(super) disp: &'a mut [u16],
    pub(super) offsets: &'a mut [i16],
    pub(super) right: &'a mut [u16],
}

/// Rows `y0..` of the outputs given to one stripe.
pub(super) struct Part<'a> {
    pub(super) y0: usize,
    pub(super) disp: &'a mut [u16],
    pub(super) offsets: &'a mut [i16],
    pub(super) right: &'a mut [u16],
}

/// Splits the output rows `r..h-r` into stripes and runs them (in parallel when there are
/// several).
pub(super) fn run<T: Term, A: Acc>(job: &Job<'_, T::F>, stripes: &mut [Stripe], outs: Outputs<'_>) {
    let Geometry { w, h, r, .. } = job.geom;
    let rows = h - 2 * r;
    let threads = stripes.len().clamp(1, rows.max(1));
    let per = rows.div_ceil(threads);
    let (mut disp, mut offsets, mut right) = (
        &mut outs.disp[r * w..(h - r) * w],
        &mut outs.offsets[r * w..(h - r) * w],
        &mut outs.right[r * w..(h - r) * w],
    );
    let mut y0 = r;
    std::thread::scope(|scope| {
        for (i, stripe) in stripes.iter_mut().take(threads).enumerate() {
            let n = per.min(disp.len() / w) * w;
            let (d, d_rest) = std::mem::take(&mut disp).split_at_mut(n);
            let (o, o_rest) = std::mem::take(&mut offsets).split_at_mut(n);
            let (rr, r_rest) = std::mem::take(&mut right).split_at_mut(n);
            (disp, offsets, right) = (d_rest, o_rest, r_rest);
            let part = Part {
                y0,
                disp: d,
                offsets: o,
                right: rr,
            };
            y0 += n / w;
            if n == 0 {
                continue;
            }
            if i + 1 == threads {
                run_stripe::<T, A>(job, stripe, part);
            } else {
                scope.spawn(move || run_stripe::<T, A>(job, stripe, part));
            }
        }
    });
}
