//! Pixel format conversions: camera formats to grey, and the 2x downscale of the fast path.
//!
//! Grey is luma: the `Y` bytes of YUYV as they are, and for colour JPEGs the BT.601 luma of
//! the decoded RGB (`(77 R + 150 G + 29 B + 128) >> 8`), which gives back the JPEG's own `Y`
//! plane to within rounding.

use std::io::Cursor;

use image::ImageDecoder;
use image::codecs::jpeg::JpegDecoder;

/// Why an image could not be converted.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConvertError {
    /// A buffer has the wrong length for the stated size.
    #[error("{what} holds {actual} bytes, expected {expected} for {width}x{height}")]
    BufferSize {
        /// Which buffer.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        actual: usize,
        /// Stated width.
        width: usize,
        /// Stated height.
        height: usize,
    },
    /// A YUYV row stride is shorter than two bytes per pixel.
    #[error("YUYV stride of {stride_bytes} bytes is too short for width {width} (needs {})", 2 * width)]
    Stride {
        /// Bytes per row as reported by the driver.
        stride_bytes: usize,
        /// Image width in pixels.
        width: usize,
    },
    /// A JPEG frame could not be decoded.
    #[error("MJPEG frame ({bytes} bytes) cannot be decoded: {message}")]
    Jpeg {
        /// Length of the frame.
        bytes: usize,
        /// The decoder's message.
        message: String,
    },
    /// A JPEG frame decoded to another size than the camera mode.
    #[error("MJPEG frame is {actual_width}x{actual_height}, expected {width}x{height}")]
    JpegSize {
        /// Decoded width.
        actual_width: u32,
        /// Decoded height.
        actual_height: u32,
        /// Expected width.
        width: usize,
        /// Expected height.
        height: usize,
    },
    /// A JPEG frame has a colour type this converter does not handle.
    #[error("MJPEG frame has colour type {color:?}; only grey and RGB JPEGs are supported")]
    JpegColor {
        /// The decoder's colour type.
        color: image::ColorType,
    },
}

fn check_len(
    what: &'static str,
    buf: &[u8],
    expected: usize,
    width: usize,
    height: usize,
) -> Result<(), ConvertError> {
    if buf.len() != expected {
        return Err(ConvertError::BufferSize {
            what,
            expected,
            actual: buf.len(),
            width,
            height,
        });
    }
    Ok(())
}

/// Extracts the luma of a packed YUYV (`Y0 U Y1 V`) image into `dst` (`width x height` grey).
/// `stride_bytes` is the driver's bytes per row (at least `2 * width`); `src` must hold at
/// least `stride_bytes * (height - 1) + 2 * width` bytes (drivers may report more).
pub fn yuyv_to_grey(
    src: &[u8],
    width: usize,
    height: usize,
    stride_bytes: usize,
    dst: &mut [u8],
) -> Result<(), ConvertError> {
    if stride_bytes < 2 * width {
        return Err(ConvertError::Stride {
            stride_bytes,
            width,
        });
    }
    check_len("grey destination", dst, width * height, width, height)?;
    let needed = if height == 0 {
        0
    } else {
        stride_bytes * (height - 1) + 2 * width
    };
    if src.len() < needed {
        return Err(ConvertError::BufferSize {
            what: "YUYV frame",
            expected: needed,
            actual: src.len(),
            width,
            height,
        });
    }
    for (y, out_row) in dst.chunks_exact_mut(width.max(1)).enumerate() {
        let row = &src[y * stride_bytes..y * stride_bytes + 2 * width];
        for (out, px) in out_row.iter_mut().zip(row.chunks_exact(2)) {
            *out = px[0];
        }
    }
    Ok(())
}

/// BT.601 luma of an RGB pixel, rounded.
fn luma(r: u8, g: u8, b: u8) -> u8 {
    ((77 * r as u32 + 150 * g as u32 + 29 * b as u32 + 128) >> 8) as u8
}

/// Decodes MJPEG frames to grey, reusing one scratch buffer for colour frames.
#[derive(Debug, Default)]
pub struct MjpegToGrey {
    scratch: Vec<u8>,
}

impl MjpegToGrey {
    /// A decoder with an empty scratch buffer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Decodes one JPEG frame (`jpeg`, the bytes the driver filled) into `dst`, which must be
    /// `width x height`; the frame must decode to exactly that size.
    pub fn convert(
        &mut self,
        jpeg: &[u8],
        width: usize,
        height: usize,
        dst: &mut [u8],
    ) -> Result<(), ConvertError> {
        check_len("grey destination", dst, width * height, width, height)?;
        let jpeg_error = |e: image::ImageError| ConvertError::Jpeg {
            bytes: jpeg.len(),
            message: e.to_string(),
        };
        let decoder = JpegDecoder::new(Cursor::new(jpeg)).map_err(jpeg_error)?;
        let (w, h) = decoder.dimensions();
        if w as usize != width || h as usize != height {
            return Err(ConvertError::JpegSize {
                actual_width: w,
                actual_height: h,
                width,
                height,
            });
        }
        match decoder.color_type() {
            image::ColorType::L8 => decoder.read_image(dst).map_err(jpeg_error),
            image::ColorType::Rgb8 => {
                self.scratch.resize(width * height * 3, 0);
                decoder.read_image(&mut self.scratch).map_err(jpeg_error)?;
                for (out, px) in dst.iter_mut().zip(self.scratch.chunks_exact(3)) {
                    *out = luma(px[0], px[1], px[2]);
                }
                Ok(())
            }
            color => Err(ConvertError::JpegColor { color }),
        }
    }
}

/// Halves a grey image in both directions with a 2x2 box average (rounded): `src` is
/// `width x height` (both even), `dst` is `width/2 x height/2`.
pub fn downscale_2x(
    src: &[u8],
    width: usize,
    height: usize,
    dst: &mut [u8],
) -> Result<(), ConvertError> {
    if src.len() != width * height || !width.is_multiple_of(2) || !height.is_multiple_of(2) {
        return Err(ConvertError::BufferSize {
            what: "source image",
            expected: width * height,
            actual: src.len(),
            width,
            height,
        });
    }
    let (dw, dh) = (width / 2, height / 2);
    check_len("destination image", dst, dw * dh, dw, dh)?;
    if dw == 0 {
        return Ok(());
    }
    for (y, out_row) in dst.chunks_exact_mut(dw).enumerate() {
        let top = &src[2 * y * width..(2 * y + 1) * width];
        let bottom = &src[(2 * y + 1) * width..(2 * y + 2) * width];
        for (x, out) in out_row.iter_mut().enumerate() {
            let sum = top[2 * x] as u16
                + top[2 * x + 1] as u16
                + bottom[2 * x] as u16
                + bottom[2 * x + 1] as u16;
            *out = ((sum + 2) / 4) as u8;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::codecs::jpeg::JpegEncoder;
    use image::{ExtendedColorType, ImageEncoder};

    #[test]
    fn downscale_averages_blocks() {
        let src = [0u8, 4, 10, 10, 8, 4, 10, 11];
        let mut dst = [0u8; 2];
        downscale_2x(&src, 4, 2, &mut dst).unwrap();
        assert_eq!(dst, [4, 10]); // (0+4+8+4)/4 = 4, (10+10+10+11+2)/4 = 10
    }

    #[test]
    fn downscale_rejects_wrong_sizes() {
        let mut dst = [0u8; 4];
        let err = downscale_2x(&[0u8; 15], 4, 4, &mut dst).unwrap_err();
        assert!(err.to_string().contains("4x4"), "{err}");
        let err = downscale_2x(&[0u8; 16], 4, 4, &mut [0u8; 3]).unwrap_err();
        assert!(err.to_string().contains("destination"), "{err}");
    }

    #[test]
    fn yuyv_takes_the_luma_bytes() {
        // 4x2 image: Y values 10, 20, ..., chroma bytes 128/255 must be ignored.
        let src = [
            10, 128, 20, 255, 30, 128, 40, 255, //
            50, 128, 60, 255, 70, 128, 80, 255,
        ];
        let mut dst = [0u8; 8];
        yuyv_to_grey(&src, 4, 2, 8, &mut dst).unwrap();
        assert_eq!(dst, [10, 20, 30, 40, 50, 60, 70, 80]);
    }

    #[test]
    fn yuyv_honours_the_row_stride() {
        // 2x2 image with 2 padding bytes (0xEE) after each 4-byte row; last row unpadded.
        let src = [1, 0, 2, 0, 0xEE, 0xEE, 3, 0, 4, 0];
        let mut dst = [0u8; 4];
        yuyv_to_grey(&src, 2, 2, 6, &mut dst).unwrap();
        assert_eq!(dst, [1, 2, 3, 4]);
    }

    #[test]
    fn yuyv_rejects_short_frames_and_strides() {
        let mut dst = [0u8; 8];
        let err = yuyv_to_grey(&[0u8; 15], 4, 2, 8, &mut dst).unwrap_err();
        assert!(
            err.to_string().contains("YUYV frame holds 15 bytes"),
            "{err}"
        );
        let err = yuyv_to_grey(&[0u8; 16], 4, 2, 6, &mut dst).unwrap_err();
        assert!(err.to_string().contains("stride of 6 bytes"), "{err}");
        let err = yuyv_to_grey(&[0u8; 16], 4, 2, 8, &mut [0u8; 7]).unwrap_err();
        assert!(err.to_string().contains("grey destination"), "{err}");
    }

    fn gradient(width: usize, height: usize) -> Vec<u8> {
        (0..width * height)
            .map(|i| {
                ((i % width) * 255 / (width - 1)) as u8 / 2 + ((i / width) * 100 / height) as u8
            })
            .collect()
    }

    fn encode_jpeg(
        pixels: &[u8],
        width: usize,
        height: usize,
        color: ExtendedColorType,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        JpegEncoder::new_with_quality(&mut out, 95)
            .write_image(pixels, width as u32, height as u32, color)
            .unwrap();
        out
    }

    fn max_diff(a: &[u8], b: &[u8]) -> u8 {
        a.iter()
            .zip(b)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap_or(0)
    }

    #[test]
    fn mjpeg_grey_frame_decodes_to_its_pixels() {
        let (w, h) = (64, 48);
        let grey = gradient(w, h);
        let jpeg = encode_jpeg(&grey, w, h, ExtendedColorType::L8);
        let mut dst = vec![0u8; w * h];
        MjpegToGrey::new().convert(&jpeg, w, h, &mut dst).unwrap();
        assert!(max_diff(&dst, &grey) <= 6, "{}", max_diff(&dst, &grey));
    }

    #[test]
    fn mjpeg_colour_frame_decodes_to_its_luma() {
        let (w, h) = (64, 48);
        let grey = gradient(w, h);
        // A grey scene in RGB: the luma must be the grey value.
        let rgb: Vec<u8> = grey.iter().flat_map(|&g| [g, g, g]).collect();
        let jpeg = encode_jpeg(&rgb, w, h, ExtendedColorType::Rgb8);
        let mut dst = vec![0u8; w * h];
        let mut decoder = MjpegToGrey::new();
        decoder.convert(&jpeg, w, h, &mut dst).unwrap();
        assert!(max_diff(&dst, &grey) <= 6, "{}", max_diff(&dst, &grey));
        assert_eq!(luma(255, 0, 0), 77);
        assert_eq!(luma(255, 255, 255), 255);
    }

    #[test]
    fn mjpeg_errors_name_the_problem() {
        let mut decoder = MjpegToGrey::new();
        let mut dst = vec![0u8; 64 * 48];
        let err = decoder
            .convert(&[0xFF, 0xD8, 0x00, 0x01], 64, 48, &mut dst)
            .unwrap_err();
        assert!(err.to_string().contains("MJPEG frame (4 bytes)"), "{err}");
        let jpeg = encode_jpeg(&gradient(32, 24), 32, 24, ExtendedColorType::L8);
        let err = decoder.convert(&jpeg, 64, 48, &mut dst).unwrap_err();
        assert!(err.to_string().contains("32x24, expected 64x48"), "{err}");
    }
}
