//! The diffusion variant (OpenVis3D): soft matches diffused along columns (cut at horizontal
//! edges) and rows, goodness = row support x column support.

use super::params::MatchFunction;
use super::prepare::Prepared;
use super::wta::Wta;

/// OpenVis3D's `alpha` of the diffusion variant: soft match `exp(-alpha/255 * BT)` ("smaller
/// alpha, smoother"). Its default, 20, is kept.
pub const DIFFUSION_ALPHA: f32 = 20.0;

/// Soft match of the diffusion variant with [`MatchFunction::Census`]: `exp(-beta * hamming)`.
pub const CENSUS_BETA: f32 = 0.5;

/// Diffusion goodness below which a hypothesis is not offered to the winner-take-all: a pixel
/// whose every hypothesis is weaker stays invalid instead of taking noise. (A lone perfect match
/// scores 1; a lone census match at Hamming distance 4 scores 0.14^2 = 0.02.)
pub const DIFFUSION_MIN_GOODNESS: f32 = 0.01;

/// Scratch of the diffusion variant.
#[derive(Debug, Default)]
pub(super) struct Diffusion {
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
    pub(super) fn prepare_lut(&mut self, f: MatchFunction) {
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
    pub(super) fn run(&mut self, prep: &Prepared, hi: usize, wta: &mut Wta) {
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
