//! Refinements shared by the matchers: left-right consistency, speckle removal, subpixel fits
//! and a 3x3 median. Disparity maps are in 1/256 px with 0 = invalid.

use hvs_shared::messages::DISPARITY_SCALE;

/// Parabola through (-1, c_minus), (0, c0), (1, c_plus): offset of its minimum in
/// [-0.5, 0.5], or 0 when the costs are not convex.
pub fn parabola_offset(c_minus: f32, c0: f32, c_plus: f32) -> f32 {
    let denom = c_minus - 2.0 * c0 + c_plus;
    if denom > 0.0 {
        ((c_minus - c_plus) / (2.0 * denom)).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// A disparity in px to the 1/256-px map encoding (0 stays reserved for invalid).
pub fn to_q8(disparity_px: f32) -> u16 {
    let q = (disparity_px * DISPARITY_SCALE).round();
    if q < 1.0 {
        // A real disparity of (nearly) zero cannot be told from "invalid"; keep it valid.
        1
    } else {
        q.min(u16::MAX as f32) as u16
    }
}

/// Left-right consistency check. `right_q8` is the disparity map of the right image (a right
/// pixel `x` with disparity `d` matches left pixel `x + d`). Left pixels whose partner is
/// outside the image, invalid, or disagrees by more than `max_diff_px` become invalid.
/// Returns the number of pixels invalidated.
pub fn lr_check(left_q8: &mut [u16], right_q8: &[u16], width: usize, max_diff_px: u32) -> usize {
    let max_diff = max_diff_px as i32 * DISPARITY_SCALE as i32;
    let mut removed = 0;
    for (lrow, rrow) in left_q8
        .chunks_exact_mut(width)
        .zip(right_q8.chunks_exact(width))
    {
        for (x, d) in lrow.iter_mut().enumerate() {
            if *d == 0 {
                continue;
            }
            let xr = x as i32 - ((*d as i32 + 128) >> 8);
            let ok = xr >= 0 && {
                let dr = rrow[xr as usize];
                dr != 0 && (dr as i32 - *d as i32).abs() <= max_diff
            };
            if !ok {
                *d = 0;
                removed += 1;
            }
        }
    }
    removed
}

/// Removes speckles: 4-connected regions (neighbours within `max_diff_px`) of at most
/// `max_size` pixels become invalid. `labels` and `sizes` are scratch buffers reused across
/// calls (no allocation once they have grown). Returns the number of pixels removed.
///
/// Two-pass connected-component labelling with a union-find forest whose parents always
/// point to smaller indices (union by minimum): every pass reads the map in scan order, which
/// measured about twice as fast as a breadth-first flood fill (its jumps between rows miss the
/// cache and its queue branches unpredictably).
pub fn speckle_filter(
    disp_q8: &mut [u16],
    width: usize,
    height: usize,
    max_size: usize,
    max_diff_px: u32,
    labels: &mut Vec<u32>,
    sizes: &mut Vec<u32>,
) -> usize {
    if max_size == 0 || width == 0 {
        return 0;
    }
    let n = width * height;
    debug_assert!(disp_q8.len() >= n && n < u32::MAX as usize);
    labels.clear();
    labels.resize(n, 0);
    let max_diff = (max_diff_px as f32 * DISPARITY_SCALE) as i32;
    let near = |a: u16, b: u16| b != 0 && (a as i32 - b as i32).abs() <= max_diff;
    // Root of `i` with path halving; parents are never larger than their children.
    fn find(labels: &mut [u32], mut i: u32) -> u32 {
        while labels[i as usize] != i {
            let parent = labels[i as usize];
            labels[i as usize] = labels[parent as usize];
            i = parent;
        }
        i
    }
    // Pass 1: link every valid pixel to its left and upper neighbours.
    for y in 0..height {
        for x in 0..width {
            let p = y * width + x;
            let d = disp_q8[p];
            if d == 0 {
                continue;
            }
            let left = x > 0 && near(d, disp_q8[p - 1]);
            let up = y > 0 && near(d, disp_q8[p - width]);
            labels[p] = match (left, up) {
                (false, false) => p as u32,
                (true, false) => labels[p - 1],
                (false, true) => labels[p - width],
                (true, true) => {
                    let (l, u) = (labels[p - 1], labels[p - width]);
                    let a = find(labels, l);
                    let b = find(labels, u);
                    let (lo, hi) = (a.min(b), a.max(b));
                    labels[hi as usize] = lo;
                    lo
                }
            };
        }
    }
    // Pass 2: flatten (a parent precedes its child, so it is already a root) and count.
    sizes.clear();
    sizes.resize(n, 0);
    for p in 0..n {
        if disp_q8[p] != 0 {
            let root = labels[labels[p] as usize];
            labels[p] = root;
            sizes[root as usize] += 1;
        }
    }
    // Pass 3: clear the pixels of small regions.
    let mut removed = 0;
    for p in 0..n {
        if disp_q8[p] != 0 && sizes[labels[p] as usize] as usize <= max_size {
            disp_q8[p] = 0;
            removed += 1;
        }
    }
    removed
}

/// 3x3 median of a disparity map (invalid pixels take part as 0; borders copied).
pub fn median3x3(src: &[u16], width: usize, height: usize, dst: &mut [u16]) {
    dst.copy_from_slice(src);
    if width < 3 || height < 3 {
        return;
    }
    for y in 1..height - 1 {
        for x in 1..width - 1 {
            let mut v = [0u16; 9];
            let mut k = 0;
            for dy in 0..3 {
                for dx in 0..3 {
                    v[k] = src[(y + dy - 1) * width + x + dx - 1];
                    k += 1;
                }
            }
            v.sort_unstable();
            dst[y * width + x] = v[4];
        }
    }
}

/// Fills runs of invalid pixels of at most `max_gap` along each row from the background
/// side: with a valid disparity on both ends of the run, the smaller (farther) one, since a
/// pixel that fails the left-right check next to a depth edge is most often background the
/// foreground occludes in the other view; runs touching the image border are left alone.
/// Returns the pixels filled.
pub fn fill_from_background(q8: &mut [u16], width: usize, max_gap: usize) -> usize {
    let mut filled = 0;
    for row in q8.chunks_exact_mut(width.max(1)) {
        let mut x = 0;
        while x < row.len() {
            if row[x] != 0 {
                x += 1;
                continue;
            }
            let start = x;
            while x < row.len() && row[x] == 0 {
                x += 1;
            }
            let len = x - start;
            if start == 0 || x == row.len() || len > max_gap {
                continue;
            }
            let fill = row[start - 1].min(row[x]);
            row[start..x].fill(fill);
            filled += len;
        }
    }
    filled
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parabola_finds_the_vertex() {
        // y = (x - 0.25)^2 sampled at -1, 0, 1.
        let f = |x: f32| (x - 0.25) * (x - 0.25);
        assert!((parabola_offset(f(-1.0), f(0.0), f(1.0)) - 0.25).abs() < 1e-6);
        assert_eq!(parabola_offset(1.0, 1.0, 1.0), 0.0);
    }

    #[test]
    fn lr_check_keeps_consistent_pairs_only() {
        let w = 8;
        let q = |d: f32| to_q8(d);
        // Left x=5 has d=2 -> right x=3 must say 2; left x=6 has d=2 -> right x=4 says 5.
        let mut left = vec![0u16; w];
        left[5] = q(2.0);
        left[6] = q(2.0);
        left[1] = q(3.0); // partner at x = -2: outside
        let mut right = vec![0u16; w];
        right[3] = q(2.5);
        right[4] = q(5.0);
        assert_eq!(lr_check(&mut left, &right, w, 1), 2);
        assert_eq!(left[5], q(2.0));
        assert_eq!(left[6], 0);
        assert_eq!(left[1], 0);
    }

    #[test]
    fn small_regions_are_removed_large_ones_kept() {
        let (w, h) = (10, 6);
        let mut d = vec![to_q8(20.0); w * h];
        // A 2x2 island of a very different disparity, and one invalid pixel.
        for (x, y) in [(3, 2), (4, 2), (3, 3), (4, 3)] {
            d[y * w + x] = to_q8(40.0);
        }
        d[0] = 0;
        let (mut labels, mut stack) = (Vec::new(), Vec::new());
        let removed = speckle_filter(&mut d, w, h, 4, 1, &mut labels, &mut stack);
        assert_eq!(removed, 4);
        assert_eq!(d[2 * w + 3], 0);
        assert_eq!(d[5 * w + 9], to_q8(20.0));
        // A slanted region (steps of 1 px) is one region and survives.
        let mut ramp: Vec<u16> = (0..w * h).map(|i| to_q8(10.0 + (i % w) as f32)).collect();
        assert_eq!(
            speckle_filter(&mut ramp, w, h, 4, 1, &mut labels, &mut stack),
            0
        );
    }

    /// Straightforward flood-fill speckle removal: the reference the fast filter must match.
    fn speckle_reference(d: &mut [u16], w: usize, h: usize, max_size: usize, max_diff: i32) {
        let mut seen = vec![false; w * h];
        for start in 0..w * h {
            if d[start] == 0 || seen[start] {
                continue;
            }
            seen[start] = true;
            let mut region = vec![start];
            let mut head = 0;
            while head < region.len() {
                let p = region[head];
                head += 1;
                let (x, y) = (p % w, p / w);
                let mut nbrs = Vec::new();
                if x > 0 {
                    nbrs.push(p - 1);
                }
                if x + 1 < w {
                    nbrs.push(p + 1);
                }
                if y > 0 {
                    nbrs.push(p - w);
                }
                if y + 1 < h {
                    nbrs.push(p + w);
                }
                for q in nbrs {
                    if !seen[q] && d[q] != 0 && (d[q] as i32 - d[p] as i32).abs() <= max_diff {
                        seen[q] = true;
                        region.push(q);
                    }
                }
            }
            if region.len() <= max_size {
                for p in region {
                    d[p] = 0;
                }
            }
        }
    }

    #[test]
    fn speckle_filter_matches_a_flood_fill_on_random_maps() {
        // A small LCG: deterministic, no extra dependency.
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as u32
        };
        let (mut labels, mut sizes) = (Vec::new(), Vec::new());
        for case in 0..200 {
            let (w, h) = (1 + next() as usize % 40, 1 + next() as usize % 30);
            // Few levels and many holes: U-shaped regions that merge late are common.
            let levels = 2 + case % 5;
            let holes = next() % 60;
            let map: Vec<u16> = (0..w * h)
                .map(|_| {
                    if next() % 100 < holes {
                        0
                    } else {
                        to_q8(10.0 + (next() % levels) as f32)
                    }
                })
                .collect();
            let max_size = next() as usize % 12;
            let mut fast = map.clone();
            let mut slow = map.clone();
            let removed = speckle_filter(&mut fast, w, h, max_size, 1, &mut labels, &mut sizes);
            speckle_reference(&mut slow, w, h, max_size, 256);
            assert_eq!(fast, slow, "case {case}: {w}x{h}, max_size {max_size}");
            let expected = map.iter().zip(&slow).filter(|(a, b)| a != b).count();
            assert_eq!(removed, expected, "case {case}");
        }
    }

    #[test]
    fn median_removes_an_isolated_outlier() {
        let (w, h) = (5, 5);
        let mut src = vec![100u16; w * h];
        src[12] = 9000;
        let mut dst = vec![0u16; w * h];
        median3x3(&src, w, h, &mut dst);
        assert_eq!(dst[12], 100);
    }
}
