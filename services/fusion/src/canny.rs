//! Integer Canny edge detector: 5x5 binomial smoothing, 3x3 Sobel, L1 magnitude, non-maximum
//! suppression in four directions, double threshold with 8-connected hysteresis.
//!
//! Written by hand because the crate implementation (`imageproc::edges::canny`) works in f32
//! with a fixed sigma and takes about 7 ms at 320x240 on the target machine; this one stays in
//! integers and reuses its buffers.

/// Reusable Canny state: buffers sized for the last image seen.
#[derive(Debug, Default)]
pub struct Canny {
    smooth_h: Vec<u16>,
    smooth: Vec<u16>,
    magnitude: Vec<u16>,
    direction: Vec<u8>,
    stack: Vec<u32>,
}

/// Marker for an edge pixel in the output map.
pub const EDGE: u8 = 255;

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
        let n = width * height;
        assert_eq!(image.len(), n, "image size");
        assert_eq!(edges.len(), n, "edge map size");
        edges.fill(0);
        if width < 5 || height < 5 {
            return 0;
        }
        self.smooth_h.resize(n, 0);
        self.smooth.resize(n, 0);
        self.magnitude.clear();
        self.magnitude.resize(n, 0);
        self.direction.resize(n, 0);

        // Separable [1 4 6 4 1] smoothing; result scaled by 256 (fits u16: 255 * 256).
        for y in 0..height {
            let row = &image[y * width..(y + 1) * width];
            let out = &mut self.smooth_h[y * width..(y + 1) * width];
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
                let s = self.smooth_h[r0 + x] as u32
                    + 4 * self.smooth_h[r1 + x] as u32
                    + 6 * self.smooth_h[r2 + x] as u32
                    + 4 * self.smooth_h[r3 + x] as u32
                    + self.smooth_h[r4 + x] as u32;
                // Back to 8-bit grey scale with one fractional bit kept (x2).
                self.smooth[r2 + x] = ((s + 64) >> 7) as u16;
            }
        }

        // Sobel on the smoothed image (which is grey x 2, so magnitudes are halved back).
        let (tan22_q15, tan67_q15) = (13_573i32, 79_109i32);
        for y in 1..height - 1 {
            for x in 1..width - 1 {
                let p = |dx: isize, dy: isize| {
                    self.smooth[(y as isize + dy) as usize * width + (x as isize + dx) as usize]
                        as i32
                };
                let gx = (p(1, -1) + 2 * p(1, 0) + p(1, 1)) - (p(-1, -1) + 2 * p(-1, 0) + p(-1, 1));
                let gy = (p(-1, 1) + 2 * p(0, 1) + p(1, 1)) - (p(-1, -1) + 2 * p(0, -1) + p(1, -1));
                let (gx, gy) = (gx / 2, gy / 2);
                let i = y * width + x;
                self.magnitude[i] =
                    (gx.unsigned_abs() + gy.unsigned_abs()).min(u16::MAX as u32) as u16;
                let (ax, ay) = (gx.abs() << 15, gy.abs() << 15);
                // 0: horizontal gradient (vertical edge), 1: 45 deg, 2: vertical gradient, 3: 135 deg.
                self.direction[i] = if ay < tan22_q15 * gx.abs() {
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

        // Non-maximum suppression: keep a pixel if it beats its neighbours across the edge.
        // Strong maxima seed the hysteresis; weak maxima are marked 1 for now.
        self.stack.clear();
        for y in 1..height - 1 {
            for x in 1..width - 1 {
                let i = y * width + x;
                let m = self.magnitude[i] as u32;
                if m < low {
                    continue;
                }
                let (a, b) = match self.direction[i] {
                    0 => (i - 1, i + 1),
                    2 => (i - width, i + width),
                    1 => (i - width - 1, i + width + 1),
                    _ => (i - width + 1, i + width - 1),
                };
                // Ties: '>' on one side and '>=' on the other keeps exactly one of a plateau.
                if m > self.magnitude[a] as u32 && m >= self.magnitude[b] as u32 {
                    if m >= high {
                        edges[i] = EDGE;
                        self.stack.push(i as u32);
                    } else {
                        edges[i] = 1;
                    }
                }
            }
        }

        // Hysteresis: grow strong edges through 8-connected weak maxima.
        let mut count = self.stack.len();
        while let Some(i) = self.stack.pop() {
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
                        self.stack.push(j as u32);
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
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
