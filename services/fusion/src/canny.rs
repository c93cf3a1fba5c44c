//! Integer Canny edge detector: 5x5 binomial smoothing, 3x3 Sobel, L1 magnitude, non-maximum
//! suppression in four directions, double threshold with 8-connected hysteresis.
//!
//! Written by hand because the crate implementation (`imageproc::edges::canny`) works in f32
//! with a fixed sigma and takes about 7 ms at 320x240 on the target machine; this one stays in
//! integers and reuses its buffers.
//!
//! The passes run row by row in one sweep (smoothing row `y`, Sobel row `y - 1`, suppression
//! row `y - 2`) over small ring buffers that stay in L1 cache, and every inner loop is plain
//! slice code with the borders handled apart, so the compiler vectorises it; on x86_64 the same
//! code is also compiled for AVX2 and picked at run time. Hysteresis is a depth-first growth
//! from the strong maxima that tests 8 pixels, or the 3 neighbours in a row, per load.
//! Measured (`canny_timing`, median of 200 frames of blocky texture plus noise, one core of the
//! 2-core AVX2 target, other core busy): 0.15-0.23 ms at 320x240 (0.2-0.3 ms without AVX2) and
//! 0.7-0.95 ms at 640x480, against 2-3 ms and 8-12 ms for the first, straightforward version.

/// Fixed-point (Q15) tangents of 22.5 and 67.5 degrees, bounding the direction classes.
const TAN22_Q15: i32 = 13_573;
const TAN67_Q15: i32 = 79_109;

/// Largest L1 magnitude: |gx / 2| + |gy / 2| with |gx|, |gy| <= 4 * 510.
const MAX_MAGNITUDE: u32 = 2040;

/// Reusable Canny state: row buffers sized for the last image width seen, and the
/// hysteresis stack.
#[derive(Debug, Default)]
pub struct Canny {
    /// One row of vertical [1 4 6 4 1] sums of the image (before the horizontal pass).
    column: Vec<u16>,
    /// Ring of 3 smoothed rows (grey x 2), row `y` in slot `y % 3`.
    smooth: Vec<u16>,
    /// Ring of 3 magnitude rows, row `y` in slot `y % 3`; border columns are 0.
    magnitude: Vec<u16>,
    /// Ring of 2 direction-class rows, row `y` in slot `y % 2`.
    direction: Vec<u16>,
    stack: Vec<u32>,
}

/// Marker for an edge pixel in the output map.
pub const EDGE: u8 = 255;

/// Labels of the working edge map before hysteresis: a weak maximum (at least `low`), a strong
/// one (at least `high`, a hysteresis seed) and a weak one reached from a strong one. Each is
/// one bit, so hysteresis can test 8 pixels at a time.
const WEAK: u8 = 1;
const STRONG: u8 = 2;
const GROWN: u8 = 4;

impl Canny {
    /// Creates an empty detector.
    pub fn new() -> Self {
        Self::default()
    }

    /// Detects edges of `image` (`width x height` grey) into `edges` (255 = edge, 0 = not),
    /// with thresholds on the L1 Sobel magnitude of the smoothed image (range 0..=2040).
    /// Returns the number of edge pixels. Images smaller than 5x5 give no edges.
    pub fn detect(
        &mut self,
        image: &[u8],
        width: usize,
        height: usize,
        low: u32,
        high: u32,
        edges: &mut [u8],
    ) -> usize {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2, checked just above.
            return unsafe { self.detect_avx2(image, width, height, low, high, edges) };
        }
        self.detect_portable(image, width, height, low, high, edges)
    }

    /// [`Self::detect`] compiled for AVX2: the same code, with 16 pixels per vector instead
    /// of 8.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn detect_avx2(
        &mut self,
        image: &[u8],
        width: usize,
        height: usize,
        low: u32,
        high: u32,
        edges: &mut [u8],
    ) -> usize {
        self.detect_portable(image, width, height, low, high, edges)
    }

    /// [`Self::detect`] for any CPU (SSE2 on x86_64); inlined into [`Self::detect_avx2`].
    #[inline(always)]
    fn detect_portable(
        &mut self,
        image: &[u8],
        width: usize,
        height: usize,
        low: u32,
        high: u32,
        edges: &mut [u8],
    ) -> usize {
        let n = width * height;
        assert_eq!(image.len(), n, "image size");
        assert_eq!(edges.len(), n, "edge map size");
        if width < 5 || height < 5 {
            edges.fill(0);
            return 0;
        }
        let w = width;
        self.column.resize(w, 0);
        self.smooth.resize(3 * w, 0);
        self.magnitude.resize(3 * w, 0);
        self.direction.resize(2 * w, 0);
        self.stack.resize(n, 0);
        // Magnitudes never exceed 2040, so thresholds above 2041 act like 2041 and fit u16.
        let low = low.min(MAX_MAGNITUDE + 1) as u16;
        let high = high.min(MAX_MAGNITUDE + 1) as u16;

        // The one-pixel border has no gradient: magnitude row 0 (slot 0) and the first and
        // last edge rows are 0 (the suppression pass writes the border columns).
        self.magnitude[..w].fill(0);
        edges[..w].fill(0);
        edges[(height - 1) * w..].fill(0);

        let row = |y: usize| &image[y * w..(y + 1) * w];
        for y in 0..height {
            let clamp = |y: usize, dy: isize| (y as isize + dy).clamp(0, height as isize - 1);
            let rows = [-2, -1, 0, 1, 2].map(|dy| row(clamp(y, dy) as usize));
            smooth_row(rows, &mut self.column, slot_mut(&mut self.smooth, w, y % 3));
            if y >= 2 {
                // Sobel row y - 1 needs smoothed rows y - 2 ..= y.
                let s = |r: usize| slot(&self.smooth, w, r % 3);
                sobel_row(
                    [s(y - 2), s(y - 1), s(y)],
                    slot_mut(&mut self.magnitude, w, (y - 1) % 3),
                    slot_mut(&mut self.direction, w, (y - 1) % 2),
                );
            }
            if y >= 3 {
                self.suppress_row(y - 2, w, low, high, edges);
            }
        }
        // Magnitude row height - 1 is border (0); then the last inner row.
        slot_mut(&mut self.magnitude, w, (height - 1) % 3).fill(0);
        self.suppress_row(height - 2, w, low, high, edges);

        let count = hysteresis(edges, w, &mut self.stack);
        for e in edges.iter_mut() {
            *e = if *e > WEAK { EDGE } else { 0 };
        }
        count
    }

    /// Non-maximum suppression and double threshold of inner row `y` into `edges`.
    #[inline(always)]
    fn suppress_row(&mut self, y: usize, w: usize, low: u16, high: u16, edges: &mut [u8]) {
        let m = |r: usize| slot(&self.magnitude, w, r % 3);
        suppress_row(
            [m(y - 1), m(y), m(y + 1)],
            slot(&self.direction, w, y % 2),
            low,
            high,
            &mut edges[y * w..(y + 1) * w],
        );
    }
}

#[inline(always)]
fn slot<T>(ring: &[T], w: usize, k: usize) -> &[T] {
    &ring[k * w..(k + 1) * w]
}

#[inline(always)]
fn slot_mut<T>(ring: &mut [T], w: usize, k: usize) -> &mut [T] {
    &mut ring[k * w..(k + 1) * w]
}

/// One row of separable [1 4 6 4 1] smoothing with edge replication, from the five image
/// rows `y - 2 ..= y + 2` (already clamped): vertical sums first (exact, so the order of the
/// two passes does not matter), then the horizontal pass, scaled back by 128 with rounding to
/// grey x 2. All sums fit u16: 16 * 16 * 255 + 64 = 65344.
#[inline(always)]
fn smooth_row(rows: [&[u8]; 5], column: &mut [u16], out: &mut [u16]) {
    let w = out.len();
    let [r0, r1, r2, r3, r4] = rows.map(|r| &r[..w]);
    let column = &mut column[..w];
    for x in 0..w {
        column[x] =
            r0[x] as u16 + 4 * (r1[x] as u16 + r3[x] as u16) + 6 * r2[x] as u16 + r4[x] as u16;
    }
    let c = &column[..];
    let tap = |x: usize| {
        let at = |dx: isize| c[(x as isize + dx).clamp(0, w as isize - 1) as usize];
        (at(-2) + at(2) + 4 * (at(-1) + at(1)) + 6 * at(0) + 64) >> 7
    };
    for x in [0, 1, w - 2, w - 1] {
        out[x] = tap(x);
    }
    let inner = &mut out[2..w - 2];
    let k = inner.len();
    let (c0, c1, c2, c3, c4) = (
        &c[..k],
        &c[1..k + 1],
        &c[2..k + 2],
        &c[3..k + 3],
        &c[4..k + 4],
    );
    for x in 0..k {
        inner[x] = (c0[x] + c4[x] + 4 * (c1[x] + c3[x]) + 6 * c2[x] + 64) >> 7;
    }
}

/// 3x3 Sobel of the middle of three smoothed rows (grey x 2, so gradients are halved back,
/// rounding towards zero): L1 magnitude and direction class per inner pixel. The border
/// columns of `magnitude` are set to 0; those of `direction` are left alone (never read).
#[inline(always)]
fn sobel_row(rows: [&[u16]; 3], magnitude: &mut [u16], direction: &mut [u16]) {
    let w = magnitude.len();
    magnitude[0] = 0;
    magnitude[w - 1] = 0;
    let k = w - 2;
    let [s0, s1, s2] = rows;
    // Columns x - 1 (a), x (b) and x + 1 (c) of the rows above (0), at (1) and below (2).
    let (a0, a1, a2) = (&s0[..k], &s1[..k], &s2[..k]);
    let (b0, b2) = (&s0[1..k + 1], &s2[1..k + 1]);
    let (c0, c1, c2) = (&s0[2..k + 2], &s1[2..k + 2], &s2[2..k + 2]);
    let magnitude = &mut magnitude[1..k + 1];
    let direction = &mut direction[1..k + 1];
    for x in 0..k {
        // Each weighted sum is at most 4 * 510, so i16 holds everything.
        let gx = (c0[x] + 2 * c1[x] + c2[x]) as i16 - (a0[x] + 2 * a1[x] + a2[x]) as i16;
        let gy = (a2[x] + 2 * b2[x] + c2[x]) as i16 - (a0[x] + 2 * b0[x] + c0[x]) as i16;
        let (gx, gy) = (gx / 2, gy / 2);
        magnitude[x] = gx.unsigned_abs() + gy.unsigned_abs();
        direction[x] = direction_class(gx, gy);
    }
}

/// Direction class of a halved gradient: 0: horizontal gradient (vertical edge), 1: 45 deg,
/// 2: vertical gradient, 3: 135 deg. The classes are bounded by the Q15 tests
/// `|gy| << 15 < TAN22_Q15 * |gx|` (0) and `|gy| << 15 > TAN67_Q15 * |gx| || gx == 0` (2),
/// evaluated here exactly in 16 bits so that a vector holds twice as many pixels: with
/// `f = floor(TAN22_Q15 * |gx| / 2^15)` (a high-half multiply), `TAN67_Q15 = 2^16 + TAN22_Q15`
/// and `TAN22_Q15 * |gx|` a multiple of 2^15 only for `gx == 0` (13573 is odd), they read
/// `gx != 0 && |gy| <= f` and `gx == 0 || |gy| - 2 |gx| > f`. |gx|, |gy| <= 1020.
#[inline(always)]
fn direction_class(gx: i16, gy: i16) -> u16 {
    const _: () = assert!(TAN67_Q15 == (1 << 16) + TAN22_Q15 && TAN22_Q15 % 2 == 1);
    let (ax, ay) = (gx.abs(), gy.abs());
    let f = ((ax as i32 * (2 * TAN22_Q15)) >> 16) as i16;
    let near_horizontal = (ax != 0) & (ay <= f);
    let near_vertical = (ax == 0) | (ay - 2 * ax > f);
    let diagonal = if (gx > 0) == (gy > 0) { 1 } else { 3 };
    if near_horizontal {
        0
    } else if near_vertical {
        2
    } else {
        diagonal
    }
}

/// Non-maximum suppression and double threshold of the middle of three magnitude rows: a
/// pixel is kept if it is at least `low`, beats its neighbour before it across the edge and
/// ties or beats the one after it ('>' on one side and '>=' on the other keeps exactly one
/// of a plateau). Writes STRONG (at least `high`), WEAK or 0; the border columns get 0.
#[inline(always)]
fn suppress_row(rows: [&[u16]; 3], direction: &[u16], low: u16, high: u16, out: &mut [u8]) {
    let w = out.len();
    out[0] = 0;
    out[w - 1] = 0;
    let k = w - 2;
    let [m0, m1, m2] = rows;
    let (ul, u, ur) = (&m0[..k], &m0[1..k + 1], &m0[2..k + 2]);
    let (l, c, r) = (&m1[..k], &m1[1..k + 1], &m1[2..k + 2]);
    let (dl, d, dr) = (&m2[..k], &m2[1..k + 1], &m2[2..k + 2]);
    let direction = &direction[1..k + 1];
    let out = &mut out[1..k + 1];
    for x in 0..k {
        // Branch-free so that it vectorises: all neighbours are loaded, then masked.
        let m = c[x];
        let dir = direction[x];
        let pick = |class: u16, v: u16| 0u16.wrapping_sub((dir == class) as u16) & v;
        let a = pick(0, l[x]) | pick(1, ul[x]) | pick(2, u[x]) | pick(3, ur[x]);
        let b = pick(0, r[x]) | pick(1, dr[x]) | pick(2, d[x]) | pick(3, dl[x]);
        let keep = (m >= low) & (m > a) & (m >= b);
        // keep ? (strong ? STRONG : WEAK) : 0.
        out[x] = 0u8.wrapping_sub(keep as u8) & (WEAK + (m >= high) as u8 * (STRONG - WEAK));
    }
}

/// Hysteresis over a map of 0 / WEAK / STRONG labels (`w` wide, border all 0): every weak
/// maximum 8-connected to a strong one through weak maxima becomes GROWN. Returns the number
/// of STRONG and GROWN pixels. `stack` must be as long as the map: each pixel is stacked at
/// most once.
///
/// Strong pixels are found 8 at a time (a word with no STRONG bit is skipped) and grown at
/// once, depth first. Only inner pixels carry labels, so the neighbours of a stacked pixel are
/// in bounds; the three neighbours in each row are tested with one 4-byte load.
#[inline(always)]
fn hysteresis(labels: &mut [u8], w: usize, stack: &mut [u32]) -> usize {
    let bytes = |labels: &[u8], at: usize| {
        u32::from_le_bytes(labels[at..at + 4].try_into().expect("4 bytes"))
    };
    // The WEAK neighbours of a pixel are gathered as bits 0, 8, 16 (row above, left to
    // right), 1, 17 (left, right) and 2, 10, 18 (row below); their offsets by bit:
    let w = w as isize;
    let mut offsets = [0isize; 32];
    for (bit, offset) in [
        (0, -w - 1),
        (8, -w),
        (16, 1 - w),
        (1, -1),
        (17, 1),
        (2, w - 1),
        (10, w),
        (18, w + 1),
    ] {
        offsets[bit] = offset;
    }
    let w = w as usize;
    let mut count = 0;
    let last = labels.len() - 8; // the map has at least 5x5 pixels
    for base in (0..labels.len()).step_by(8) {
        // The last word may overlap the one before it: its first bytes are done already.
        let start = base.min(last);
        let word = u64::from_le_bytes(labels[start..start + 8].try_into().expect("8 bytes"));
        // STRONG is bit 1 of a byte (WEAK is bit 0, GROWN bit 2).
        let mut strong = word & 0x0202_0202_0202_0202 & (u64::MAX << (8 * (base - start)));
        while strong != 0 {
            stack[0] = (start + strong.trailing_zeros() as usize / 8) as u32;
            strong &= strong - 1;
            count += 1;
            let mut top = 1;
            while top > 0 {
                top -= 1;
                let i = stack[top] as usize;
                let mut weak = (bytes(labels, i - w - 1) & 0x01_01_01)
                    | (bytes(labels, i - 1) & 0x01_00_01) << 1
                    | (bytes(labels, i + w - 2) >> 8 & 0x01_01_01) << 2;
                while weak != 0 {
                    let j = i.wrapping_add_signed(offsets[weak.trailing_zeros() as usize]);
                    weak &= weak - 1;
                    labels[j] = GROWN;
                    count += 1;
                    stack[top] = j as u32;
                    top += 1;
                }
            }
        }
    }
    count
}

/// Sobel edges (the reference's alternative): `edges[i] = EDGE` where the L1 magnitude
/// `|gx| + |gy|` of a 3x3 Sobel on `image` is at least `threshold` (0..=2040), else 0; the
/// one-pixel border is never an edge. Returns the number of edge pixels. No smoothing, no
/// thinning: thick, noise-prone edges, which is why Canny is the default.
pub fn sobel_edges(
    image: &[u8],
    width: usize,
    height: usize,
    threshold: u32,
    edges: &mut [u8],
) -> usize {
    let n = width * height;
    assert_eq!(image.len(), n, "image size");
    assert_eq!(edges.len(), n, "edge map size");
    edges.fill(0);
    if width < 3 || height < 3 {
        return 0;
    }
    let mut count = 0;
    for y in 1..height - 1 {
        let (r0, r1, r2) = (
            &image[(y - 1) * width..y * width],
            &image[y * width..(y + 1) * width],
            &image[(y + 1) * width..(y + 2) * width],
        );
        let out = &mut edges[y * width..(y + 1) * width];
        for x in 1..width - 1 {
            let p = |r: &[u8], dx: usize| r[x + dx - 1] as i32;
            let gx = (p(r0, 2) + 2 * p(r1, 2) + p(r2, 2)) - (p(r0, 0) + 2 * p(r1, 0) + p(r2, 0));
            let gy = (p(r2, 0) + 2 * p(r2, 1) + p(r2, 2)) - (p(r0, 0) + 2 * p(r0, 1) + p(r0, 2));
            if (gx.unsigned_abs() + gy.unsigned_abs()) >= threshold {
                out[x] = EDGE;
                count += 1;
            }
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The original (pre-optimisation) detector, kept verbatim as the reference that the
    /// optimised [`Canny::detect`] must match byte for byte.
    fn detect_reference(
        image: &[u8],
        width: usize,
        height: usize,
        low: u32,
        high: u32,
        edges: &mut [u8],
    ) -> usize {
        let n = width * height;
        assert_eq!(image.len(), n, "image size");
        assert_eq!(edges.len(), n, "edge map size");
        edges.fill(0);
        if width < 5 || height < 5 {
            return 0;
        }
        let mut smooth_h = vec![0u16; n];
        let mut smooth = vec![0u16; n];
        let mut magnitude = vec![0u16; n];
        let mut direction = vec![0u8; n];
        let mut stack: Vec<u32> = Vec::new();

        for y in 0..height {
            let row = &image[y * width..(y + 1) * width];
            let out = &mut smooth_h[y * width..(y + 1) * width];
            for x in 0..width {
                let at =
                    |dx: isize| row[(x as isize + dx).clamp(0, width as isize - 1) as usize] as u16;
                out[x] = at(-2) + 4 * at(-1) + 6 * at(0) + 4 * at(1) + at(2);
            }
        }
        for y in 0..height {
            let at = |dy: isize| (y as isize + dy).clamp(0, height as isize - 1) as usize * width;
            let (r0, r1, r2, r3, r4) = (at(-2), at(-1), at(0), at(1), at(2));
            for x in 0..width {
                let s = smooth_h[r0 + x] as u32
                    + 4 * smooth_h[r1 + x] as u32
                    + 6 * smooth_h[r2 + x] as u32
                    + 4 * smooth_h[r3 + x] as u32
                    + smooth_h[r4 + x] as u32;
                smooth[r2 + x] = ((s + 64) >> 7) as u16;
            }
        }

        let (tan22_q15, tan67_q15) = (13_573i32, 79_109i32);
        for y in 1..height - 1 {
            for x in 1..width - 1 {
                let p = |dx: isize, dy: isize| {
                    smooth[(y as isize + dy) as usize * width + (x as isize + dx) as usize] as i32
                };
                let gx = (p(1, -1) + 2 * p(1, 0) + p(1, 1)) - (p(-1, -1) + 2 * p(-1, 0) + p(-1, 1));
                let gy = (p(-1, 1) + 2 * p(0, 1) + p(1, 1)) - (p(-1, -1) + 2 * p(0, -1) + p(1, -1));
                let (gx, gy) = (gx / 2, gy / 2);
                let i = y * width + x;
                magnitude[i] = (gx.unsigned_abs() + gy.unsigned_abs()).min(u16::MAX as u32) as u16;
                let (ax, ay) = (gx.abs() << 15, gy.abs() << 15);
                direction[i] = if ay < tan22_q15 * gx.abs() {
                    0
                } else if ay > tan67_q15 * gx.abs() || ax == 0 {
                    2
                } else if (gx > 0) == (gy > 0) {
                    1
                } else {
                    3
                };
            }
        }

        for y in 1..height - 1 {
            for x in 1..width - 1 {
                let i = y * width + x;
                let m = magnitude[i] as u32;
                if m < low {
                    continue;
                }
                let (a, b) = match direction[i] {
                    0 => (i - 1, i + 1),
                    2 => (i - width, i + width),
                    1 => (i - width - 1, i + width + 1),
                    _ => (i - width + 1, i + width - 1),
                };
                if m > magnitude[a] as u32 && m >= magnitude[b] as u32 {
                    if m >= high {
                        edges[i] = EDGE;
                        stack.push(i as u32);
                    } else {
                        edges[i] = 1;
                    }
                }
            }
        }

        let mut count = stack.len();
        while let Some(i) = stack.pop() {
            let i = i as usize;
            let (x, y) = (i % width, i / width);
            for dy in -1isize..=1 {
                for dx in -1isize..=1 {
                    let (nx, ny) = (x as isize + dx, y as isize + dy);
                    if nx < 0 || ny < 0 || nx >= width as isize || ny >= height as isize {
                        continue;
                    }
                    let j = ny as usize * width + nx as usize;
                    if edges[j] == 1 {
                        edges[j] = EDGE;
                        count += 1;
                        stack.push(j as u32);
                    }
                }
            }
        }
        for e in edges.iter_mut() {
            if *e == 1 {
                *e = 0;
            }
        }
        count
    }

    /// Small deterministic PRNG (xorshift64*) so the tests need no extra dependency.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }

        fn byte(&mut self) -> u8 {
            (self.next() >> 56) as u8
        }

        fn below(&mut self, n: usize) -> usize {
            (self.next() % n as u64) as usize
        }
    }

    fn noise_image(rng: &mut Rng, w: usize, h: usize) -> Vec<u8> {
        (0..w * h).map(|_| rng.byte()).collect()
    }

    /// Blocky texture (random grey per 8x8 block) plus a little noise: many edges in all
    /// directions, like a real scene.
    fn textured_image(rng: &mut Rng, w: usize, h: usize) -> Vec<u8> {
        let (bw, bh) = (w.div_ceil(8), h.div_ceil(8));
        let blocks: Vec<u8> = (0..bw * bh).map(|_| rng.byte()).collect();
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let noise = (rng.byte() % 16) as i32 - 8;
                (blocks[(y / 8) * bw + x / 8] as i32 + noise).clamp(0, 255) as u8
            })
            .collect()
    }

    /// Steps and lines in all directions (vertical, horizontal, both diagonals, a circle)
    /// over a smooth gradient.
    fn shapes_image(w: usize, h: usize) -> Vec<u8> {
        let (cx, cy) = (w as i64 / 2, h as i64 / 2);
        let r2 = (w.min(h) as i64 / 3).pow(2);
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                let mut v = 30 + (x * 60 / w as i64) + (y * 40 / h as i64);
                if x > w as i64 / 3 {
                    v += 50; // vertical step
                }
                if y > h as i64 / 4 {
                    v += 40; // horizontal step
                }
                if (x - y).abs() <= 1 {
                    v = 250; // 45 degree line
                }
                if (x + y - w as i64 / 2).abs() == 0 {
                    v = 5; // 135 degree line, one pixel thick
                }
                if (x - cx).pow(2) + (y - cy).pow(2) < r2 {
                    v -= 25; // disc: edges in every direction
                }
                v.clamp(0, 255) as u8
            })
            .collect()
    }

    /// Smooth diagonal ramp, 0 to 250 across the image.
    fn gradient_image(w: usize, h: usize) -> Vec<u8> {
        (0..w * h)
            .map(|i| (150 * (i % w) / w + 100 * (i / w) / h) as u8)
            .collect()
    }

    const THRESHOLDS: [(u32, u32); 11] = [
        (0, 0),
        (0, 70_000),
        (70_000, 0),
        (1, 2),
        (2, 3),
        (20, 50),
        (40, 120),
        (60, 150),
        (100, 60),
        (300, 2040),
        (2041, u32::MAX),
    ];

    type Detect = fn(&mut Canny, &[u8], usize, usize, u32, u32, &mut [u8]) -> usize;

    /// Compares both code paths (`detect`, which picks AVX2 where the CPU has it, and
    /// `detect_portable`, which CPUs without it run) with the reference, byte for byte, for
    /// every threshold pair. Returns the reference's edge count summed over the pairs.
    fn assert_same(canny: &mut Canny, img: &[u8], w: usize, h: usize, what: &str) -> usize {
        let paths: [(&str, Detect); 2] = [
            ("detect", Canny::detect),
            ("detect_portable", Canny::detect_portable),
        ];
        let mut want = vec![0u8; w * h];
        let mut got = vec![0u8; w * h];
        let mut total = 0;
        for &(low, high) in &THRESHOLDS {
            want.fill(9);
            let n_want = detect_reference(img, w, h, low, high, &mut want);
            total += n_want;
            for (path, detect) in paths {
                got.fill(7); // every pixel must be written
                let n_got = detect(canny, img, w, h, low, high, &mut got);
                assert!(
                    got == want,
                    "{path}: {what} {w}x{h} thresholds ({low}, {high}): edge maps differ"
                );
                assert_eq!(n_got, n_want, "{path}: {what} {w}x{h} ({low}, {high})");
            }
        }
        total
    }

    fn check_all_images(canny: &mut Canny) {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        // Below 5x5 (no edges), tiny, odd and narrow widths (5 wide: the last word of the
        // map reaches into the last inner row), and frame sizes.
        let sizes = [
            (1, 1),
            (4, 4),
            (4, 9),
            (9, 4),
            (127, 3),
            (5, 5),
            (5, 6),
            (6, 5),
            (6, 7),
            (7, 6),
            (5, 11),
            (5, 19),
            (7, 9),
            (8, 8),
            (13, 11),
            (17, 5),
            (5, 17),
            (31, 9),
            (33, 33),
            (63, 40),
            (64, 48),
            (65, 47),
            (97, 61),
            (129, 95),
        ];
        let (mut noise, mut texture, mut shapes, mut gradient) = (0, 0, 0, 0);
        for &(w, h) in &sizes {
            for _ in 0..3 {
                noise += assert_same(canny, &noise_image(&mut rng, w, h), w, h, "noise");
            }
            let img = textured_image(&mut rng, w, h);
            texture += assert_same(canny, &img, w, h, "texture");
            shapes += assert_same(canny, &shapes_image(w, h), w, h, "shapes");
            gradient += assert_same(canny, &gradient_image(w, h), w, h, "gradient");
        }
        // A whole frame, once.
        let (w, h) = (320, 240);
        texture += assert_same(canny, &textured_image(&mut rng, w, h), w, h, "texture");
        // The images do have edges (the gradient only at the lowest thresholds).
        assert!(noise > 10_000 && texture > 10_000 && shapes > 1_000 && gradient > 0);
        // Every narrow size, and random sizes, reusing the same detector across sizes.
        for w in 5..=9 {
            for h in 5..=24 {
                assert_same(canny, &noise_image(&mut rng, w, h), w, h, "narrow noise");
            }
        }
        for _ in 0..100 {
            let (w, h) = (1 + rng.below(40), 1 + rng.below(40));
            let img = if rng.below(2) == 0 {
                noise_image(&mut rng, w, h)
            } else {
                textured_image(&mut rng, w, h)
            };
            assert_same(canny, &img, w, h, "random size");
        }
        // Extreme images: black/white checkerboards and single bright pixels.
        for &(w, h) in &[(5, 5), (6, 7), (20, 15)] {
            let checker: Vec<u8> = (0..w * h)
                .map(|i| if (i % w + i / w) % 2 == 0 { 0 } else { 255 })
                .collect();
            assert_same(canny, &checker, w, h, "checker");
            let mut dot = vec![0u8; w * h];
            dot[(h / 2) * w + w / 2] = 255;
            assert_same(canny, &dot, w, h, "dot");
        }
    }

    #[test]
    fn direction_class_matches_q15_tests() {
        for gx in -1020i32..=1020 {
            for gy in -1020i32..=1020 {
                let (ax, ay) = (gx.abs() << 15, gy.abs() << 15);
                let want = if ay < TAN22_Q15 * gx.abs() {
                    0
                } else if ay > TAN67_Q15 * gx.abs() || ax == 0 {
                    2
                } else if (gx > 0) == (gy > 0) {
                    1
                } else {
                    3
                };
                assert_eq!(direction_class(gx as i16, gy as i16), want, "({gx}, {gy})");
            }
        }
    }

    #[test]
    fn detect_matches_reference() {
        check_all_images(&mut Canny::new());
    }

    fn step_image(w: usize, h: usize, edge_x: usize) -> Vec<u8> {
        (0..w * h)
            .map(|i| if i % w < edge_x { 40 } else { 200 })
            .collect()
    }

    #[test]
    fn vertical_step_gives_one_thin_vertical_line() {
        let (w, h) = (40, 30);
        let img = step_image(w, h, 20);
        let mut edges = vec![0; w * h];
        let n = Canny::new().detect(&img, w, h, 60, 150, &mut edges);
        assert!(n > 0);
        for y in 3..h - 3 {
            let xs: Vec<usize> = (0..w).filter(|&x| edges[y * w + x] == EDGE).collect();
            assert_eq!(xs.len(), 1, "row {y}: {xs:?}");
            assert!((19..=20).contains(&xs[0]), "row {y}: {xs:?}");
        }
    }

    #[test]
    fn flat_and_noisy_low_contrast_images_give_no_edges() {
        let (w, h) = (32, 32);
        let flat = vec![128u8; w * h];
        let mut edges = vec![0; w * h];
        assert_eq!(Canny::new().detect(&flat, w, h, 20, 50, &mut edges), 0);
        let noisy: Vec<u8> = (0..w * h).map(|i| 128 + ((i * 7919) % 5) as u8).collect();
        assert_eq!(Canny::new().detect(&noisy, w, h, 20, 50, &mut edges), 0);
    }

    #[test]
    fn weak_edges_survive_only_when_connected_to_strong_ones() {
        let (w, h) = (40, 40);
        // Left: a vertical step whose contrast fades from 120 (strong) at the top to 40 (weak)
        // at the bottom: one continuous chain. Right: an isolated weak step of 40.
        let mut img = vec![100u8; w * h];
        for y in 0..h {
            let contrast = (120 - 4 * (y as i32 - 10).clamp(0, 20)) as u8;
            for x in 10..25 {
                img[y * w + x] = 100 + contrast;
            }
            for x in 30..w {
                img[y * w + x] = 140;
            }
        }
        let mut edges = vec![0; w * h];
        Canny::new().detect(&img, w, h, 40, 120, &mut edges);
        let has_edge =
            |xs: std::ops::Range<usize>, y: usize| xs.into_iter().any(|x| edges[y * w + x] == EDGE);
        assert!(has_edge(8..12, 5), "strong part");
        assert!(
            has_edge(8..12, 35),
            "weak part connected to the strong part"
        );
        assert!(!has_edge(28..33, 20), "isolated weak edge must be dropped");
    }

    #[test]
    fn sobel_marks_a_step_and_nothing_on_flat_grey() {
        let (w, h) = (16, 8);
        let mut img = vec![50u8; w * h];
        let mut edges = vec![0u8; w * h];
        assert_eq!(sobel_edges(&img, w, h, 100, &mut edges), 0);
        for y in 0..h {
            for x in 8..w {
                img[y * w + x] = 150;
            }
        }
        let n = sobel_edges(&img, w, h, 100, &mut edges);
        // Columns 7 and 8 straddle the step on every inner row.
        assert_eq!(n, 2 * (h - 2));
        assert_eq!(edges[3 * w + 7], EDGE);
        assert_eq!(edges[3 * w + 3], 0);
    }
}
