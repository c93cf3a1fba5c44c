//! Images for `hvs probe snapshot` (pure logic, no IPC): a stereo pair side by side, a
//! disparity map in a jet-like colour map with a legend bar in metres (the reference's
//! "gray2color"), and the fused map (disparity at edge pixels) over the left image.
//!
//! The legend's tick labels use a tiny built-in 3x5 bitmap font of the twelve glyphs needed
//! (`0`-`9`, `.`, `m`), drawn by hand: a font crate plus a font file would be far more than
//! twelve 15-bit patterns, and the `image` crate draws no text.

use hvs_fusion::DepthModel;
use image::{GrayImage, Luma, Rgb, RgbImage};

/// Width of the legend strip added to the right of colour-mapped images, px.
pub const LEGEND_WIDTH_PX: u32 = 72;

/// Glyph rows of the 3x5 font, top to bottom; bit 2 is the leftmost column.
fn glyph(c: char) -> Option<[u8; 5]> {
    Some(match c {
        '0' => [0b111, 0b101, 0b101, 0b101, 0b111],
        '1' => [0b010, 0b110, 0b010, 0b010, 0b111],
        '2' => [0b111, 0b001, 0b111, 0b100, 0b111],
        '3' => [0b111, 0b001, 0b111, 0b001, 0b111],
        '4' => [0b101, 0b101, 0b111, 0b001, 0b001],
        '5' => [0b111, 0b100, 0b111, 0b001, 0b111],
        '6' => [0b111, 0b100, 0b111, 0b101, 0b111],
        '7' => [0b111, 0b001, 0b001, 0b001, 0b001],
        '8' => [0b111, 0b101, 0b111, 0b101, 0b111],
        '9' => [0b111, 0b101, 0b111, 0b001, 0b111],
        '.' => [0b000, 0b000, 0b000, 0b000, 0b010],
        'm' => [0b000, 0b110, 0b111, 0b101, 0b101],
        _ => return None,
    })
}

/// Draws `text` with its top-left corner at (`x`, `y`), each font pixel a `scale` x `scale`
/// square, one font column between glyphs. Characters without a glyph are skipped (they
/// still advance); pixels outside the image are clipped. Returns the text width in px.
pub fn draw_text(
    img: &mut RgbImage,
    x: i64,
    y: i64,
    text: &str,
    scale: u32,
    colour: [u8; 3],
) -> u32 {
    let s = i64::from(scale.max(1));
    let mut cx = x;
    for c in text.chars() {
        if let Some(rows) = glyph(c) {
            for (ry, bits) in rows.iter().enumerate() {
                for rx in 0..3 {
                    if bits & (0b100 >> rx) == 0 {
                        continue;
                    }
                    for dy in 0..s {
                        for dx in 0..s {
                            put(img, cx + rx * s + dx, y + ry as i64 * s + dy, colour);
                        }
                    }
                }
            }
        }
        cx += 4 * s;
    }
    (cx - x - s).max(0) as u32
}

fn put(img: &mut RgbImage, x: i64, y: i64, colour: [u8; 3]) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, Rgb(colour));
    }
}

/// Jet-like colour map: 0 = dark blue, 0.5 = green-yellow, 1 = dark red (input clamped).
pub fn jet(t: f32) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    let ch = |centre: f32| ((1.5 - (4.0 * t - centre).abs()).clamp(0.0, 1.0) * 255.0).round() as u8;
    [ch(3.0), ch(2.0), ch(1.0)]
}

/// How disparities are coloured: linearly from `min_disp_px` (far, blue) to `max_disp_px`
/// (near, red), with the depth model to label the legend in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColourScale {
    /// Disparity mapped to the blue end, px.
    pub min_disp_px: f32,
    /// Disparity mapped to the red end, px.
    pub max_disp_px: f32,
    /// Disparity to depth (`f * b / d`).
    pub depth: DepthModel,
}

impl ColourScale {
    /// The scale for a map searched over `min_disp..=max_disp` px (a degenerate range is
    /// widened to one pixel; a minimum of 0 is raised to 1 px so depths stay finite).
    pub fn new(min_disp_px: u32, max_disp_px: u32, depth: DepthModel) -> Self {
        let lo = min_disp_px.max(1) as f32;
        let hi = (max_disp_px as f32).max(lo + 1.0);
        Self {
            min_disp_px: lo,
            max_disp_px: hi,
            depth,
        }
    }

    /// Position in [0, 1] of a disparity on the scale (0 = far end).
    pub fn position(&self, disparity_px: f32) -> f32 {
        ((disparity_px - self.min_disp_px) / (self.max_disp_px - self.min_disp_px)).clamp(0.0, 1.0)
    }

    /// Colour of a stored disparity (1/256 px); `None` for 0 (invalid).
    pub fn colour_q8(&self, disparity_q8: u16) -> Option<[u8; 3]> {
        (disparity_q8 != 0).then(|| {
            jet(self.position(f32::from(disparity_q8) / hvs_shared::messages::DISPARITY_SCALE))
        })
    }

    /// Depth at the near (red) end, metres.
    pub fn near_m(&self) -> f64 {
        self.depth.range_m(f64::from(self.max_disp_px))
    }

    /// Depth at the far (blue) end, metres.
    pub fn far_m(&self) -> f64 {
        self.depth.range_m(f64::from(self.min_disp_px))
    }
}

/// Depths worth a legend tick, metres.
const TICK_DEPTHS_M: [f64; 16] = [
    0.2, 0.3, 0.4, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 7.5, 10.0, 15.0, 20.0, 50.0,
];

/// Legend ticks of a bar `height_px` tall (row 0 = near end): (row, depth in metres), nearest
/// first, at least `min_gap_px` apart.
pub fn legend_ticks(scale: &ColourScale, height_px: u32, min_gap_px: u32) -> Vec<(u32, f64)> {
    let (near, far) = (scale.near_m(), scale.far_m());
    let mut ticks: Vec<(u32, f64)> = Vec::new();
    for depth_m in TICK_DEPTHS_M {
        if depth_m < near || depth_m > far {
            continue;
        }
        let d = (scale.depth.focal_px * scale.depth.baseline_m / depth_m) as f32;
        let row = ((1.0 - scale.position(d)) * (height_px.saturating_sub(1)) as f32).round() as u32;
        if ticks
            .last()
            .is_none_or(|&(last, _)| row >= last + min_gap_px)
        {
            ticks.push((row, depth_m));
        }
    }
    ticks
}

/// A depth label such as `0.5m`, `2m`, `7.5m`.
pub fn depth_label(depth_m: f64) -> String {
    format!("{depth_m}m")
}

/// Draws the legend (bar, ticks, labels in metres) into the strip `x0..x0 + LEGEND_WIDTH_PX`.
fn draw_legend(img: &mut RgbImage, x0: u32, scale: &ColourScale) {
    let height = img.height();
    for y in 0..height {
        for x in x0..(x0 + LEGEND_WIDTH_PX).min(img.width()) {
            img.put_pixel(x, y, Rgb([32, 32, 32]));
        }
    }
    let (top, bottom) = (8u32, height.saturating_sub(8));
    if bottom <= top + 2 {
        return;
    }
    let bar_h = bottom - top;
    let (bar_x, bar_w) = (x0 + 6, 12u32);
    for row in 0..bar_h {
        let t = 1.0 - row as f32 / (bar_h - 1) as f32;
        let c = jet(t);
        for x in bar_x..bar_x + bar_w {
            put(img, i64::from(x), i64::from(top + row), c);
        }
    }
    let text_scale = 2;
    for (row, depth_m) in legend_ticks(scale, bar_h, 14) {
        let y = i64::from(top + row);
        for x in (bar_x + bar_w)..(bar_x + bar_w + 4) {
            put(img, i64::from(x), y, [255, 255, 255]);
        }
        // Centre the 10 px tall label on the tick, kept inside the image.
        let label_y = (y - 5).clamp(0, i64::from(height) - 10);
        draw_text(
            img,
            i64::from(bar_x + bar_w + 6),
            label_y,
            &depth_label(depth_m),
            text_scale,
            [255, 255, 255],
        );
    }
}

/// A stereo pair side by side (left | right), grey, `2 * width x height`.
pub fn stereo_pair_image(left: &[u8], right: &[u8], width: u32, height: u32) -> GrayImage {
    let w = width as usize;
    GrayImage::from_fn(width * 2, height, |x, y| {
        let (img, x) = if x < width {
            (left, x)
        } else {
            (right, x - width)
        };
        Luma([img.get(y as usize * w + x as usize).copied().unwrap_or(0)])
    })
}

/// A `width x height` picture, pixel `i` (row-major) coloured by `pixel(i)`, with the legend
/// of `scale` on the right.
fn with_legend(
    width: u32,
    height: u32,
    scale: &ColourScale,
    pixel: impl Fn(usize) -> [u8; 3],
) -> RgbImage {
    let w = width as usize;
    let mut img = RgbImage::new(width + LEGEND_WIDTH_PX, height);
    for y in 0..height {
        for x in 0..width {
            img.put_pixel(x, y, Rgb(pixel(y as usize * w + x as usize)));
        }
    }
    draw_legend(&mut img, width, scale);
    img
}

/// A disparity map in the colour map (invalid pixels black) with the legend on the right:
/// `(width + LEGEND_WIDTH_PX) x height`.
pub fn disparity_image(
    disparity_q8: &[u16],
    width: u32,
    height: u32,
    scale: &ColourScale,
) -> RgbImage {
    with_legend(width, height, scale, |i| {
        let d = disparity_q8.get(i).copied().unwrap_or(0);
        scale.colour_q8(d).unwrap_or([0, 0, 0])
    })
}

/// The fused map over the left image: the left image at half brightness, and every pixel of
/// `fused_q8` with a valid disparity (edge pixels) in the colour map; legend on the right.
pub fn fused_image(
    left: &[u8],
    fused_q8: &[u16],
    width: u32,
    height: u32,
    scale: &ColourScale,
) -> RgbImage {
    with_legend(width, height, scale, |i| {
        match fused_q8.get(i).and_then(|&d| scale.colour_q8(d)) {
            Some(c) => c,
            None => {
                let g = left.get(i).copied().unwrap_or(0) / 2;
                [g, g, g]
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scale() -> ColourScale {
        ColourScale::new(
            2,
            55,
            DepthModel {
                focal_px: 320.0,
                baseline_m: 0.06,
            },
        )
    }

    #[test]
    fn jet_runs_blue_to_red() {
        assert_eq!(jet(0.0), [0, 0, 128]);
        assert_eq!(jet(1.0), [128, 0, 0]);
        let mid = jet(0.5);
        assert_eq!(mid[1], 255, "green peaks in the middle: {mid:?}");
        assert_eq!(jet(-3.0), jet(0.0));
    }

    #[test]
    fn scale_colours_near_red_far_blue_and_invalid_none() {
        let s = scale();
        assert_eq!(s.colour_q8(0), None);
        assert_eq!(s.colour_q8(55 * 256), Some(jet(1.0)));
        assert_eq!(s.colour_q8(2 * 256), Some(jet(0.0)));
        assert!((s.near_m() - 19.2 / 55.0).abs() < 1e-9);
        assert!((s.far_m() - 9.6).abs() < 1e-9);
    }

    #[test]
    fn ticks_lie_in_range_in_order_and_apart() {
        let s = scale();
        let ticks = legend_ticks(&s, 224, 12);
        assert!(ticks.len() >= 3, "{ticks:?}");
        assert_eq!(
            ticks[0].1, 0.4,
            "nearest nice depth above 0.35 m: {ticks:?}"
        );
        for pair in ticks.windows(2) {
            assert!(pair[1].0 >= pair[0].0 + 12, "{ticks:?}");
            assert!(pair[1].1 > pair[0].1);
        }
        // Depth 1 m is disparity 19.2 px: row (1 - (19.2 - 2) / 53) * 223.
        let one = ticks.iter().find(|t| t.1 == 1.0).expect("1 m tick");
        assert_eq!(one.0, ((1.0 - 17.2 / 53.0) * 223.0f32).round() as u32);
        assert_eq!(depth_label(0.5), "0.5m");
        assert_eq!(depth_label(2.0), "2m");
    }

    #[test]
    fn text_draws_known_glyph_pixels() {
        let mut img = RgbImage::new(40, 12);
        let w = draw_text(&mut img, 1, 1, "1.5m", 1, [255, 0, 0]);
        assert_eq!(w, 4 * 4 - 1);
        // '1': top row has only the middle column lit.
        assert_eq!(img.get_pixel(1, 1).0, [0, 0, 0]);
        assert_eq!(img.get_pixel(2, 1).0, [255, 0, 0]);
        // '.': lit at the bottom middle of the second cell.
        assert_eq!(img.get_pixel(6, 5).0, [255, 0, 0]);
        // Clipping: drawing off the image does not panic.
        draw_text(&mut img, 38, 10, "888", 3, [1, 1, 1]);
        assert_eq!(glyph('x'), None);
    }

    #[test]
    fn images_have_the_expected_sizes_and_content() {
        let left = vec![200u8; 8 * 4];
        let right = vec![10u8; 8 * 4];
        let pair = stereo_pair_image(&left, &right, 8, 4);
        assert_eq!(pair.dimensions(), (16, 4));
        assert_eq!(pair.get_pixel(7, 3).0, [200]);
        assert_eq!(pair.get_pixel(8, 0).0, [10]);

        let s = scale();
        let mut disp = vec![0u16; 32 * 24];
        disp[0] = 55 * 256;
        let img = disparity_image(&disp, 32, 24, &s);
        assert_eq!(img.dimensions(), (32 + LEGEND_WIDTH_PX, 24));
        assert_eq!(img.get_pixel(0, 0).0, jet(1.0));
        assert_eq!(img.get_pixel(1, 0).0, [0, 0, 0]);

        let left = vec![100u8; 32 * 24];
        let fused = fused_image(&left, &disp, 32, 24, &s);
        assert_eq!(fused.get_pixel(0, 0).0, jet(1.0));
        assert_eq!(fused.get_pixel(5, 5).0, [50, 50, 50]);
    }
}
