//! The images prepared for matching: the half-interval bounds of the Birchfield-Tomasi
//! dissimilarity (or census strings), one resampled right image per stretch factor, the
//! horizontal edges that cut vertical links, the hypotheses, and the mean/std equalisation.

use super::params::{MatchFunction, OgaleParams};

/// Census window of [`MatchFunction::Census`] (5x5: 24 comparisons).
const CENSUS_WIN: usize = 5;

/// One matching hypothesis: left `x` against column `x - s` of the right image resampled with
/// factor `m` (right position `m * (x - s)`), valid on columns `xa..xb` of every row.
#[derive(Debug, Clone, Copy)]
pub(super) struct Hypothesis {
    /// Index of the resampled right image.
    pub(super) image: usize,
    /// Whether the factor is exactly 1 (disparity `s` everywhere).
    pub(super) unit: bool,
    /// Shift in resampled columns.
    pub(super) s: isize,
    /// First valid column.
    pub(super) xa: usize,
    /// One past the last valid column.
    pub(super) xb: usize,
}

/// The right image resampled with one stretch factor, prepared for matching.
#[derive(Debug, Default)]
pub(super) struct RightImage {
    /// Stretch factor.
    pub(super) m: f32,
    /// Width (resampled columns `x'` with `m * x' <= w - 1`).
    pub(super) w: usize,
    /// Grey values.
    pub(super) grey: Vec<u8>,
    /// `2*R`, `R + min(R)`, `R + max(R)` over the match function's neighbourhood.
    pub(super) v2: Vec<u16>,
    pub(super) lo2: Vec<u16>,
    pub(super) hi2: Vec<u16>,
    /// Census strings (only with [`MatchFunction::Census`]).
    pub(super) census: Vec<u32>,
    /// Original right position of every resampled column, 1/256 px: `round(256 * m * x')`.
    pub(super) pos_q8: Vec<i32>,
}

/// The images prepared for matching, and the hypotheses.
#[derive(Debug, Default)]
pub(super) struct Prepared {
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) match_fn: MatchFunction,
    pub(super) vertical_search: usize,
    /// Left `2*L`, `L + min(L)`, `L + max(L)`.
    pub(super) l2: Vec<u16>,
    pub(super) llo2: Vec<u16>,
    pub(super) lhi2: Vec<u16>,
    /// Left census strings (only with [`MatchFunction::Census`]).
    pub(super) lcensus: Vec<u32>,
    /// One right image per distinct stretch factor, fronto-parallel first.
    pub(super) right: Vec<RightImage>,
    /// Per row boundary `y | y+1`: prefix counts of uncut vertical links (`w + 1` per boundary).
    pub(super) uncut_prefix: Vec<u32>,
    /// Per row boundary `y | y+1`: 1.0 where the vertical link holds, 0.0 where it is cut.
    pub(super) link: Vec<f32>,
    pub(super) hyps: Vec<Hypothesis>,
    /// Scratch.
    pub(super) resampled: Vec<u8>,
    pub(super) tmp: Vec<u8>,
    pub(super) tmp_min: Vec<u8>,
    pub(super) tmp_max: Vec<u8>,
}

impl Prepared {
    pub(super) fn prepare(
        &mut self,
        left: &[u8],
        right: &[u8],
        w: usize,
        h: usize,
        p: &OgaleParams,
    ) {
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
pub(super) fn equalize_mean_std(left: &[u8], right: &[u8], out: &mut [u8]) {
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
