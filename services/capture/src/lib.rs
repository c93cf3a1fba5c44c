//! hvs capture: turns camera output into the pipeline's stereo frames, with no IPC.
//!
//! One capture feeds both paths: the 640x480 pair for the long-range worker and a 320x240 pair
//! for the fast path, downscaled once, directly into the loaned shared-memory sample.

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
    if dst.len() != dw * dh {
        return Err(ConvertError::BufferSize {
            what: "destination image",
            expected: dw * dh,
            actual: dst.len(),
            width: dw,
            height: dh,
        });
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
}
