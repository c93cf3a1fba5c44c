//! The components variant: binary matches per hypothesis, runs of matches, a run-length
//! union-find over rows linked where no horizontal edge cuts them, goodness = component size.

use super::prepare::Prepared;
use super::wta::Wta;

/// Scratch of the components variant.
#[derive(Debug, Default)]
pub(super) struct Components {
    cost: Vec<u16>,
    cost_tmp: Vec<u16>,
    /// Match bits of one row (bit `x % 64` of word `x / 64`).
    bits: Vec<u64>,
    /// Runs `(x0, x1)` (x1 exclusive) of matching pixels, row by row.
    runs: Vec<(u16, u16)>,
    /// First run of every row (`h + 1` entries).
    row_start: Vec<u32>,
    parent: Vec<u32>,
    size: Vec<u32>,
}

impl Components {
    /// One hypothesis: binary matches, runs, run-length union-find, then every matching pixel
    /// offers its component size (in left pixels) to the winner-take-all.
    pub(super) fn run(&mut self, prep: &Prepared, hi: usize, thr: u16, cut: bool, wta: &mut Wta) {
        let hyp = prep.hyps[hi];
        let (w, h) = (prep.w, prep.h);
        let words = w.div_ceil(64);
        self.cost.resize(words * 64, u16::MAX);
        self.bits.resize(words, 0);
        self.runs.clear();
        self.row_start.clear();
        let (wa, wb) = (hyp.xa / 64, hyp.xb.div_ceil(64));
        for y in 0..h {
            self.row_start.push(self.runs.len() as u32);
            prep.cost_row(y, &hyp, &mut self.cost, &mut self.cost_tmp);
            // Pack the matches into bits; the band mask drops columns outside xa..xb.
            for (k, word) in self.bits[wa..wb].iter_mut().enumerate() {
                let chunk = &self.cost[(wa + k) * 64..(wa + k + 1) * 64];
                let mut v = 0u64;
                for (i, &c) in chunk.iter().enumerate() {
                    v |= u64::from(c <= thr) << i;
                }
                *word = v;
            }
            // Runs from the bits: alternately the next set and the next clear bit.
            let mut start: Option<usize> = None;
            for k in wa..wb {
                let lo = hyp.xa.max(k * 64) - k * 64;
                let hi = hyp.xb.min(k * 64 + 64) - k * 64;
                let band = if hi == 64 { u64::MAX } else { (1u64 << hi) - 1 } & (u64::MAX << lo);
                let v = self.bits[k] & band;
                let mut pos = 0u32;
                while pos < 64 {
                    let rest = if start.is_none() { v >> pos } else { !v >> pos };
                    if rest == 0 {
                        break;
                    }
                    pos += rest.trailing_zeros();
                    let x = k * 64 + pos as usize;
                    match start {
                        None => start = Some(x),
                        Some(x0) => {
                            self.runs.push((x0 as u16, x as u16));
                            start = None;
                        }
                    }
                }
            }
            if let Some(x0) = start {
                self.runs.push((x0 as u16, hyp.xb as u16));
            }
        }
        self.row_start.push(self.runs.len() as u32);
        let nr = self.runs.len();
        self.parent.clear();
        self.parent.extend(0..nr as u32);
        // Vertical links between overlapping runs of consecutive rows, unless every column of
        // the overlap is cut by a horizontal edge.
        for y in 1..h {
            let (a0, a1) = (self.row_start[y - 1] as usize, self.row_start[y] as usize);
            let b1 = self.row_start[y + 1] as usize;
            let (mut i, mut j) = (a0, a1);
            let pre = cut.then(|| &prep.uncut_prefix[(y - 1) * (w + 1)..y * (w + 1)]);
            while i < a1 && j < b1 {
                let (ra, rb) = (self.runs[i], self.runs[j]);
                let (lo, hi) = (ra.0.max(rb.0) as usize, ra.1.min(rb.1) as usize);
                if lo < hi && pre.is_none_or(|pre| pre[hi] > pre[lo]) {
                    union(&mut self.parent, i as u32, j as u32);
                }
                if ra.1 < rb.1 {
                    i += 1;
                } else {
                    j += 1;
                }
            }
        }
        // Component sizes in pixels, kept at the roots.
        self.size.clear();
        self.size.resize(nr, 0);
        for r in 0..nr {
            let root = find(&mut self.parent, r as u32) as usize;
            self.parent[r] = root as u32;
            let (x0, x1) = self.runs[r];
            self.size[root] += (x1 - x0) as u32;
        }
        for y in 0..h {
            let row = y * w;
            for r in self.row_start[y] as usize..self.row_start[y + 1] as usize {
                let g = self.size[self.parent[r] as usize] as f32;
                let (x0, x1) = (self.runs[r].0 as usize, self.runs[r].1 as usize);
                if hyp.unit {
                    let (d_q8, s) = (256 * hyp.s as i32, hyp.s as usize);
                    for x in x0..x1 {
                        wta.offer(row + x, row + x - s, g, d_q8, hi as u32);
                    }
                } else {
                    for x in x0..x1 {
                        let (d_q8, q) = prep.disparity_at(&hyp, x);
                        wta.offer(row + x, row + q, g, d_q8, hi as u32);
                    }
                }
            }
        }
    }
}

/// Union-find root with path halving.
#[inline]
fn find(parent: &mut [u32], mut a: u32) -> u32 {
    while parent[a as usize] != a {
        let gp = parent[parent[a as usize] as usize];
        parent[a as usize] = gp;
        a = gp;
    }
    a
}

/// Joins the sets of `a` and `b` (the smaller root index becomes the root).
#[inline]
fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        parent[hi as usize] = lo;
    }
}
