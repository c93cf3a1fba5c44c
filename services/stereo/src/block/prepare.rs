//! Per-frame preparation: box sums, the texture measure of the left image and the window
//! statistics of NCC (computed once per frame, independent of the disparity).

/// Box sums of `vals` over a `(2r+1)^2` window for the pixels whose window lies inside the
/// image (others 0), with running column and row sums.
fn box_sums(vals: &[i32], w: usize, h: usize, r: usize, out: &mut Vec<i32>, col: &mut Vec<i32>) {
    let win = 2 * r + 1;
    out.clear();
    out.resize(w * h, 0);
    col.clear();
    col.resize(w, 0);
    if w < win || h < win {
        return;
    }
    for y in 0..h {
        for (c, &v) in col.iter_mut().zip(&vals[y * w..(y + 1) * w]) {
            *c += v;
        }
        if y >= win {
            for (c, &v) in col.iter_mut().zip(&vals[(y - win) * w..(y - win + 1) * w]) {
                *c -= v;
            }
        }
        if y + 1 >= win {
            let row = &mut out[(y - r) * w..(y - r + 1) * w];
            let mut s: i32 = col[..win].iter().sum();
            row[r] = s;
            for x in r + 1..w - r {
                s += col[x + r] - col[x - r - 1];
                row[x] = s;
            }
        }
    }
}

/// Window sums of `|L(x+1) - L(x-1)|` (edge pixels repeated).
pub(super) fn texture_into(
    left: &[u8],
    w: usize,
    h: usize,
    r: usize,
    values: &mut Vec<i32>,
    out: &mut Vec<i32>,
    col: &mut Vec<i32>,
) {
    values.clear();
    for row in left.chunks_exact(w) {
        for x in 0..w {
            let a = row[x.saturating_sub(1)] as i32;
            let b = row[(x + 1).min(w - 1)] as i32;
            values.push((a - b).abs());
        }
    }
    box_sums(values, w, h, r, out, col);
}

/// Scratch for the NCC window statistics.
pub(super) struct NccScratch<'a> {
    pub(super) values: &'a mut Vec<i32>,
    pub(super) sum: &'a mut Vec<i32>,
    pub(super) sq: &'a mut Vec<i32>,
    pub(super) col: &'a mut Vec<i32>,
}

impl NccScratch<'_> {
    /// Per-pixel window sums `S = sum(I - 128)` and `1 / sqrt(n * sum((I - 128)^2) - S^2)` (0
    /// for a window of under a quarter grey level of standard deviation).
    pub(super) fn compute(
        &mut self,
        img: &[u8],
        w: usize,
        h: usize,
        r: usize,
        sum_out: &mut Vec<f32>,
        inv_out: &mut Vec<f32>,
    ) {
        let area = ((2 * r + 1) * (2 * r + 1)) as i64;
        self.values.clear();
        self.values.extend(img.iter().map(|&p| p as i32 - 128));
        box_sums(self.values, w, h, r, self.sum, self.col);
        for v in self.values.iter_mut() {
            *v *= *v;
        }
        box_sums(self.values, w, h, r, self.sq, self.col);
        sum_out.clear();
        inv_out.clear();
        let flat = area * area / 4;
        for (&s, &q) in self.sum.iter().zip(self.sq.iter()) {
            let var_n = area * q as i64 - (s as i64) * (s as i64);
            sum_out.push(s as f32);
            inv_out.push(if var_n > flat {
                (1.0 / (var_n as f64).sqrt()) as f32
            } else {
                0.0
            });
        }
    }
}
