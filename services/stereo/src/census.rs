//! Census transforms: each pixel becomes a bit string saying which neighbours are darker than
//! it; two pixels are compared by the Hamming distance of their strings. The result depends
//! only on the order of grey values, so a gain or offset between the cameras changes nothing.
//!
//! The interior of the image (where the window needs no clamping) runs 32 pixels at a time with
//! AVX2 when the CPU has it (detected at run time); borders and other CPUs use the scalar code.
//! Both give identical strings.

/// Census transform with an odd `win_w x win_h` window (at most 33 pixels: 32 comparisons):
/// bit k is set when neighbour k (row-major, centre skipped) is darker than the centre.
/// Pixels outside the image repeat the nearest edge pixel.
pub fn census(
    img: &[u8],
    width: usize,
    height: usize,
    win_w: usize,
    win_h: usize,
    out: &mut [u32],
) {
    census_with(img, width, height, win_w, win_h, out, true);
}

/// [`census`] with the SIMD interior switched on or off (`simd = false` forces the scalar
/// code, for tests and benchmarks; `true` still falls back to scalar without AVX2).
pub fn census_with(
    img: &[u8],
    width: usize,
    height: usize,
    win_w: usize,
    win_h: usize,
    out: &mut [u32],
    simd: bool,
) {
    assert_eq!(img.len(), width * height, "image size");
    assert_eq!(out.len(), width * height, "output size");
    assert!(
        win_w % 2 == 1 && win_h % 2 == 1 && win_w * win_h <= 33,
        "census window {win_w}x{win_h}"
    );
    if width == 0 || height == 0 {
        return;
    }
    let (rx, ry) = (win_w / 2, win_h / 2);
    #[cfg(target_arch = "x86_64")]
    let simd = simd && width >= 2 * rx + 32 && crate::cpu::avx2();
    #[cfg(not(target_arch = "x86_64"))]
    let simd = {
        let _ = simd;
        false
    };
    #[cfg(target_arch = "x86_64")]
    let (mut pad, window) = ([0u8; EDGE_PAD], avx2::Window::new(rx, ry));
    for y in 0..height {
        let row = &mut out[y * width..(y + 1) * width];
        if simd {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: AVX2 was detected above, width >= 2 * rx + 32 and the window has at most
            // 33 pixels (so rx, ry <= 16), which is all `census_row_avx2` needs.
            unsafe {
                avx2::census_row_avx2(img, width, y, &window, row, &mut pad);
            }
        } else {
            for (x, o) in row.iter_mut().enumerate() {
                *o = census_pixel(img, width, height, x, y, rx, ry);
            }
        }
    }
}

/// The census string of one pixel (scalar; clamps at the borders).
#[inline]
fn census_pixel(
    img: &[u8],
    width: usize,
    height: usize,
    x: usize,
    y: usize,
    rx: usize,
    ry: usize,
) -> u32 {
    let (rx, ry) = (rx as isize, ry as isize);
    let clamp_x = |x: isize| x.clamp(0, width as isize - 1) as usize;
    let clamp_y = |y: isize| y.clamp(0, height as isize - 1) as usize;
    let fast = x as isize >= rx
        && y as isize >= ry
        && x as isize + rx < width as isize
        && y as isize + ry < height as isize;
    let c = img[y * width + x];
    let mut bits = 0u32;
    let mut k = 0;
    for dy in -ry..=ry {
        for dx in -rx..=rx {
            if dx == 0 && dy == 0 {
                continue;
            }
            let p = if fast {
                img[(y as isize + dy) as usize * width + (x as isize + dx) as usize]
            } else {
                img[clamp_y(y as isize + dy) * width + clamp_x(x as isize + dx)]
            };
            bits |= u32::from(p < c) << k;
            k += 1;
        }
    }
    bits
}

/// Bytes of the padded rows used for the edge columns: 33 rows of `PITCH` bytes.
#[cfg(target_arch = "x86_64")]
const PITCH: usize = 64;
#[cfg(target_arch = "x86_64")]
const EDGE_PAD: usize = 33 * PITCH;

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{EDGE_PAD, PITCH};
    use core::arch::x86_64::*;

    /// The comparisons of a window in bit order: `(window row, column offset from the
    /// window's left edge)` of neighbour `k`, for `k < n`.
    pub(super) struct Window {
        offsets: [(u8, u8); 32],
        n: usize,
        rx: usize,
        ry: usize,
    }

    impl Window {
        pub(super) fn new(rx: usize, ry: usize) -> Self {
            let mut offsets = [(0u8, 0u8); 32];
            let mut n = 0;
            for i in 0..=2 * ry {
                for j in 0..=2 * rx {
                    if (i, j) != (ry, rx) {
                        offsets[n] = (i as u8, j as u8);
                        n += 1;
                    }
                }
            }
            Self { offsets, n, rx, ry }
        }
    }

    /// The four byte planes (bits 0..8, 8..16, 16..24, 24..32) of the census strings of the
    /// 32 pixels at `base + rows[ry] + x`, where window row `i` starts at `base + rows[i]`.
    /// Each plane is built by doubling and subtracting the compare masks (0 or -1) of its
    /// eight neighbours, last bit first, so no bit constants are needed.
    ///
    /// # Safety
    /// The CPU must have AVX2; bytes `rows[i] + x - rx .. rows[i] + x + rx + 32` must be
    /// readable from `base` for every window row `i`.
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn census_chunk(
        base: *const u8,
        rows: &[usize; 33],
        x: usize,
        win: &Window,
    ) -> [__m256i; 4] {
        let flip = _mm256_set1_epi8(i8::MIN);
        let load = |at: usize| {
            // SAFETY: the caller guarantees the bytes are readable; loadu needs no alignment.
            unsafe { _mm256_loadu_si256(base.add(at).cast()) }
        };
        let c = _mm256_xor_si256(load(rows[win.ry] + x), flip);
        let left = x - win.rx;
        let mut acc = [_mm256_setzero_si256(); 4];
        for (p, plane) in acc.iter_mut().enumerate() {
            for k in (8 * p..(8 * p + 8).min(win.n)).rev() {
                let (i, j) = win.offsets[k];
                let p = _mm256_xor_si256(load(rows[i as usize] + left + j as usize), flip);
                // darker: -1 where the neighbour is darker than the centre.
                let darker = _mm256_cmpgt_epi8(c, p);
                *plane = _mm256_sub_epi8(_mm256_add_epi8(*plane, *plane), darker);
            }
        }
        acc
    }

    /// Interleaves four byte planes into 32 little-endian u32 census strings at `out`.
    ///
    /// # Safety
    /// The CPU must have AVX2; `out .. out + 32` must be writable.
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn store_strings(acc: [__m256i; 4], out: *mut u32) {
        let b01_lo = _mm256_unpacklo_epi8(acc[0], acc[1]);
        let b01_hi = _mm256_unpackhi_epi8(acc[0], acc[1]);
        let b23_lo = _mm256_unpacklo_epi8(acc[2], acc[3]);
        let b23_hi = _mm256_unpackhi_epi8(acc[2], acc[3]);
        let r0 = _mm256_unpacklo_epi16(b01_lo, b23_lo); // pixels 0..4 | 16..20
        let r1 = _mm256_unpackhi_epi16(b01_lo, b23_lo); // 4..8 | 20..24
        let r2 = _mm256_unpacklo_epi16(b01_hi, b23_hi); // 8..12 | 24..28
        let r3 = _mm256_unpackhi_epi16(b01_hi, b23_hi); // 12..16 | 28..32
        let outs = [
            _mm256_permute2x128_si256::<0x20>(r0, r1),
            _mm256_permute2x128_si256::<0x20>(r2, r3),
            _mm256_permute2x128_si256::<0x31>(r0, r1),
            _mm256_permute2x128_si256::<0x31>(r2, r3),
        ];
        for (i, v) in outs.iter().enumerate() {
            // SAFETY: the caller guarantees 32 writable u32 at `out`.
            unsafe { _mm256_storeu_si256(out.add(8 * i).cast(), *v) };
        }
    }

    /// Census strings of row `y` (window rows outside the image are clamped, as in the
    /// scalar code): the interior columns `rx..width - rx` straight from the image, 32 at a
    /// time, and the `rx` columns at each end from a small buffer of window rows padded with
    /// their repeated edge pixels.
    ///
    /// # Safety
    /// The CPU must have AVX2; `width >= 2 * rx + 32`; `row.len() == width`;
    /// `win` describes a window of at most 33 rows and `rx <= 16`.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn census_row_avx2(
        img: &[u8],
        width: usize,
        y: usize,
        win: &Window,
        row: &mut [u32],
        pad: &mut [u8; EDGE_PAD],
    ) {
        let (rx, ry) = (win.rx, win.ry);
        let height = img.len() / width;
        assert!(y < height && width >= 2 * rx + 32 && row.len() == width && ry <= 16 && rx <= 16);
        let mut rows = [0usize; 33];
        for (i, r) in rows.iter_mut().enumerate().take(2 * ry + 1) {
            *r = (y as isize + i as isize - ry as isize).clamp(0, height as isize - 1) as usize
                * width;
        }
        let x_end = width - rx;
        let mut x = rx;
        loop {
            let x0 = x.min(x_end - 32);
            // SAFETY: every rows[i] starts a row of the image, and the loads read columns
            // x0 - rx .. x0 + rx + 32 <= width of it; x0 + 32 <= width = row.len().
            unsafe {
                let acc = census_chunk(img.as_ptr(), &rows, x0, win);
                store_strings(acc, row.as_mut_ptr().add(x0));
            }
            if x0 + 32 >= x_end {
                break;
            }
            x += 32;
        }
        // The edge columns.
        let mut pad_rows = [0usize; 33];
        for (i, r) in pad_rows.iter_mut().enumerate() {
            *r = i * PITCH;
        }
        for x0 in [0, width - 32] {
            // Padded row i holds columns x0 - rx .. x0 + 32 + rx of window row i.
            for i in 0..=2 * ry {
                let src = &img[rows[i]..rows[i] + width];
                let dst = &mut pad[i * PITCH..i * PITCH + 32 + 2 * rx];
                if x0 == 0 {
                    dst[..rx].fill(src[0]);
                    dst[rx..].copy_from_slice(&src[..32 + rx]);
                } else {
                    dst[..32 + rx].copy_from_slice(&src[width - 32 - rx..]);
                    dst[32 + rx..].fill(src[width - 1]);
                }
            }
            let mut strings = [0u32; 32];
            // SAFETY: padded rows hold 32 + 2 rx <= PITCH bytes, of which the chunk at rx reads
            // columns 0 .. 2 rx + 32; `strings` has room for 32 u32.
            unsafe {
                let acc = census_chunk(pad.as_ptr(), &pad_rows, rx, win);
                store_strings(acc, strings.as_mut_ptr());
            }
            let cols = if x0 == 0 { 0..rx } else { 32 - rx..32 };
            for c in cols {
                row[x0 + c] = strings[c];
            }
        }
    }
}

/// Hamming distance of two census strings.
#[inline]
pub fn hamming(a: u32, b: u32) -> u32 {
    (a ^ b).count_ones()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn census_is_invariant_to_monotonic_intensity_maps() {
        let (w, h) = (17, 11);
        let img: Vec<u8> = (0..w * h).map(|i| ((i * 37 + i / 5) % 200) as u8).collect();
        // A strictly increasing map (gain 0.9, offset 20) keeps every comparison.
        let mapped: Vec<u8> = img.iter().map(|&p| (p as f32 * 0.9 + 20.0) as u8).collect();
        let (mut a, mut b) = (vec![0; w * h], vec![0; w * h]);
        census(&img, w, h, 5, 5, &mut a);
        census(&mapped, w, h, 5, 5, &mut b);
        let same = a.iter().zip(&b).filter(|(x, y)| x == y).count();
        // Rounding of 0.9*p can merge neighbouring grey levels; nearly every string survives.
        assert!(same * 100 >= a.len() * 95, "{same} of {}", a.len());
    }

    #[test]
    fn bits_follow_the_window_order() {
        // 3x3 window on a 3x3 image: centre 5, neighbours 1..9 without 5.
        let img = [1u8, 2, 3, 4, 5, 6, 7, 8, 9];
        let mut out = [0u32; 9];
        census(&img, 3, 3, 3, 3, &mut out);
        // Darker than 5: 1, 2, 3, 4 -> bits 0..3.
        assert_eq!(out[4], 0b0000_1111);
        assert_eq!(hamming(out[4], 0), 4);
    }

    #[test]
    fn simd_and_scalar_census_agree() {
        let mut state = 0x1234_5678_9abc_def0u64;
        for &(w, h) in &[(37, 9), (64, 7), (100, 13), (33, 5), (200, 31)] {
            let img: Vec<u8> = (0..w * h)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    // Few grey levels so that ties (not darker) occur often.
                    (state % 7) as u8 * 40
                })
                .collect();
            for &(ww, wh) in &[
                (5, 5),
                (3, 3),
                (7, 3),
                (9, 3),
                (1, 1),
                (3, 11),
                (33, 1),
                (1, 33),
            ] {
                let (mut a, mut b) = (vec![0; w * h], vec![0; w * h]);
                census_with(&img, w, h, ww, wh, &mut a, true);
                census_with(&img, w, h, ww, wh, &mut b, false);
                assert_eq!(a, b, "{w}x{h} window {ww}x{wh}");
            }
        }
    }
}
