//! Pure encoders from hvs payloads to Foxglove messages: JPEG images, the coloured disparity
//! map with its legend in metres, the fused edge map, the point cloud, the map grid, the
//! camera calibration and the frame transforms. No I/O: the worker and the tests call them.

use foxglove::bytes::Bytes;
use foxglove::messages::packed_element_field::NumericType;
use foxglove::messages::{
    CameraCalibration, CompressedImage, FrameTransform, FrameTransforms, Grid, PackedElementField,
    PointCloud, Pose, Quaternion, Timestamp, Vector2, Vector3,
};
use hvs_probe::render::{ColourScale, disparity_image, fused_image};
use hvs_probe::schemas::{CAMERA_FRAME, Pinhole, Transform, WORLD_FRAME};
use hvs_shared::messages::{DISPARITY_SCALE, NavMap};
use image::codecs::jpeg::JpegEncoder;
use image::{ExtendedColorType, ImageEncoder};

/// An image could not be encoded.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    /// The pixel buffer does not match the size.
    #[error("image of {width}x{height} needs {needed} bytes, got {got}")]
    Size {
        /// Width, px.
        width: u32,
        /// Height, px.
        height: u32,
        /// Bytes needed.
        needed: usize,
        /// Bytes given.
        got: usize,
    },
    /// The JPEG encoder failed.
    #[error("JPEG encoding failed")]
    Jpeg(#[source] image::ImageError),
}

/// A Foxglove timestamp from wall-clock ns.
pub fn stamp(wall_ns: u64) -> Timestamp {
    Timestamp::new(
        u32::try_from(wall_ns / 1_000_000_000).unwrap_or(u32::MAX),
        (wall_ns % 1_000_000_000) as u32,
    )
}

/// JPEG bytes of a grey (`channels = 1`) or RGB (`channels = 3`) image.
pub fn jpeg(
    pixels: &[u8],
    width: u32,
    height: u32,
    channels: u8,
    quality: u8,
) -> Result<Vec<u8>, EncodeError> {
    let needed = width as usize * height as usize * usize::from(channels);
    if pixels.len() != needed {
        return Err(EncodeError::Size {
            width,
            height,
            needed,
            got: pixels.len(),
        });
    }
    let colour = if channels == 1 {
        ExtendedColorType::L8
    } else {
        ExtendedColorType::Rgb8
    };
    let mut out = Vec::with_capacity(needed / 8);
    JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100))
        .write_image(pixels, width, height, colour)
        .map_err(EncodeError::Jpeg)?;
    Ok(out)
}

/// A `foxglove.CompressedImage` of JPEG bytes in the camera frame.
pub fn compressed_image(jpeg: Vec<u8>, wall_ns: u64) -> CompressedImage {
    CompressedImage {
        timestamp: Some(stamp(wall_ns)),
        frame_id: CAMERA_FRAME.to_string(),
        data: Bytes::from(jpeg),
        format: "jpeg".to_string(),
    }
}

/// The disparity map in the colour map with its legend in metres, as JPEG.
pub fn disparity_jpeg(
    disparity_q8: &[u16],
    width: u32,
    height: u32,
    scale: &ColourScale,
    quality: u8,
) -> Result<Vec<u8>, EncodeError> {
    let img = disparity_image(disparity_q8, width, height, scale);
    let (w, h) = img.dimensions();
    jpeg(img.as_raw(), w, h, 3, quality)
}

/// The fused map (disparity at the left image's edges) over the left image, with the
/// legend, as JPEG.
pub fn fused_jpeg(
    left: &[u8],
    fused_q8: &[u16],
    width: u32,
    height: u32,
    scale: &ColourScale,
    quality: u8,
) -> Result<Vec<u8>, EncodeError> {
    let img = fused_image(left, fused_q8, width, height, scale);
    let (w, h) = img.dimensions();
    jpeg(img.as_raw(), w, h, 3, quality)
}

/// Bytes per point of [`point_cloud`]: x, y, z (f32, metres) and the left image's grey level
/// (f32, 0..255).
pub const POINT_STRIDE_BYTES: usize = 16;

/// The disparity map as points in the camera's optical frame (z ahead, x right, y down),
/// every `step`-th pixel each way, at most `max_range_m` away.
pub fn point_cloud(
    disparity_q8: &[u16],
    left: &[u8],
    cal: &Pinhole,
    step: usize,
    max_range_m: f64,
    wall_ns: u64,
) -> PointCloud {
    let (w, h) = (cal.width as usize, cal.height as usize);
    let step = step.max(1);
    let mut data = Vec::with_capacity((w / step) * (h / step) * POINT_STRIDE_BYTES);
    for v in (0..h).step_by(step) {
        for u in (0..w).step_by(step) {
            let i = v * w + u;
            let Some(&d) = disparity_q8.get(i) else {
                continue;
            };
            if d == 0 {
                continue;
            }
            let z = cal.depth_m(f64::from(d) / f64::from(DISPARITY_SCALE));
            if !(z > 0.0 && z <= max_range_m) {
                continue;
            }
            let x = (u as f64 + 0.5 - cal.cx) * z / cal.focal_px;
            let y = (v as f64 + 0.5 - cal.cy) * z / cal.focal_px;
            let grey = f32::from(left.get(i).copied().unwrap_or(0));
            for f in [x as f32, y as f32, z as f32, grey] {
                data.extend_from_slice(&f.to_le_bytes());
            }
        }
    }
    let field = |name: &str, offset: u32| PackedElementField {
        name: name.to_string(),
        offset,
        r#type: NumericType::Float32 as i32,
    };
    PointCloud {
        timestamp: Some(stamp(wall_ns)),
        frame_id: CAMERA_FRAME.to_string(),
        pose: Some(identity_pose()),
        point_stride: POINT_STRIDE_BYTES as u32,
        fields: vec![
            field("x", 0),
            field("y", 4),
            field("z", 8),
            field("intensity", 12),
        ],
        data: Bytes::from(data),
    }
}

fn identity_pose() -> Pose {
    Pose {
        position: Some(Vector3 {
            x: 0.0,
            y: 0.0,
            z: 0.0,
        }),
        orientation: Some(Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }),
    }
}

/// The navigator's map as a `foxglove.Grid` in the world frame: one `occupancy` byte per
/// cell (0 free, 100 occupied, 255 unknown).
pub fn nav_grid(map: &NavMap, wall_ns: u64) -> Grid {
    let side = map.side.min(hvs_shared::messages::NAV_MAP_SIDE as u32);
    Grid {
        timestamp: Some(stamp(wall_ns)),
        frame_id: WORLD_FRAME.to_string(),
        pose: Some(Pose {
            position: Some(Vector3 {
                x: map.origin_x_m,
                y: map.origin_y_m,
                z: 0.0,
            }),
            ..identity_pose()
        }),
        column_count: side,
        cell_size: Some(Vector2 {
            x: f64::from(map.cell_m),
            y: f64::from(map.cell_m),
        }),
        row_stride: side,
        cell_stride: 1,
        fields: vec![PackedElementField {
            name: "occupancy".to_string(),
            offset: 0,
            r#type: NumericType::Uint8 as i32,
        }],
        data: Bytes::copy_from_slice(&map.cells[..(side * side) as usize]),
    }
}

/// `foxglove.CameraCalibration` of the left camera.
pub fn calibration(cal: &Pinhole, wall_ns: u64) -> CameraCalibration {
    CameraCalibration {
        timestamp: Some(stamp(wall_ns)),
        frame_id: CAMERA_FRAME.to_string(),
        width: cal.width,
        height: cal.height,
        distortion_model: "plumb_bob".to_string(),
        d: vec![0.0; 5],
        k: cal.k().to_vec(),
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: cal.p().to_vec(),
    }
}

/// `foxglove.FrameTransforms` of the transforms.
pub fn frame_transforms(transforms: &[Transform], wall_ns: u64) -> FrameTransforms {
    FrameTransforms {
        transforms: transforms
            .iter()
            .map(|t| FrameTransform {
                timestamp: Some(stamp(wall_ns)),
                parent_frame_id: t.parent.to_string(),
                child_frame_id: t.child.to_string(),
                translation: Some(Vector3 {
                    x: t.translation_m[0],
                    y: t.translation_m[1],
                    z: t.translation_m[2],
                }),
                rotation: Some(Quaternion {
                    x: t.rotation[0],
                    y: t.rotation[1],
                    z: t.rotation[2],
                    w: t.rotation[3],
                }),
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvs_fusion::DepthModel;
    use hvs_runtime::config::CameraConfig;

    fn cal() -> Pinhole {
        Pinhole::of(&CameraConfig::default(), 320, 240)
    }

    #[test]
    fn jpeg_decodes_to_the_same_size() {
        let grey: Vec<u8> = (0..320 * 240).map(|i| (i % 251) as u8).collect();
        let bytes = jpeg(&grey, 320, 240, 1, 75).expect("jpeg");
        let back = image::load_from_memory(&bytes).expect("decodes");
        assert_eq!((back.width(), back.height()), (320, 240));
        assert!(matches!(
            jpeg(&grey[1..], 320, 240, 1, 75),
            Err(EncodeError::Size { got: 76_799, .. })
        ));
    }

    #[test]
    fn the_disparity_image_carries_its_legend() {
        let scale = ColourScale::new(
            1,
            55,
            DepthModel {
                focal_px: 320.0,
                baseline_m: 0.06,
            },
        );
        let d = vec![20u16 * 256; 320 * 240];
        let bytes = disparity_jpeg(&d, 320, 240, &scale, 80).expect("jpeg");
        let back = image::load_from_memory(&bytes).expect("decodes");
        assert_eq!(
            back.width(),
            320 + hvs_probe::render::LEGEND_WIDTH_PX,
            "legend strip on the right"
        );
    }

    #[test]
    fn points_lie_at_the_depth_of_their_disparity() {
        let c = cal();
        let mut d = vec![0u16; 320 * 240];
        // Disparity 16 px at the principal point: z = f * b / 16.
        d[120 * 320 + 160] = 16 * 256;
        d[0] = 1; // 1/256 px: far beyond max_range_m, dropped
        let left = vec![200u8; 320 * 240];
        let pc = point_cloud(&d, &left, &c, 1, 8.0, 0);
        assert_eq!(pc.data.len(), POINT_STRIDE_BYTES, "one point");
        let f = |k: usize| {
            f32::from_le_bytes([pc.data[k], pc.data[k + 1], pc.data[k + 2], pc.data[k + 3]])
        };
        let z = c.focal_px * c.baseline_m / 16.0;
        assert!((f64::from(f(8)) - z).abs() < 1e-5, "z {} vs {z}", f(8));
        assert!(f(0).abs() < 0.01 && f(4).abs() < 0.01, "on the axis");
        assert_eq!(f(12), 200.0);
    }

    #[test]
    fn the_grid_spans_the_map() {
        let map = NavMap {
            origin_x_m: -6.4,
            origin_y_m: -6.4,
            cell_m: 0.1,
            ..Default::default()
        };
        let g = nav_grid(&map, 1);
        assert_eq!(g.data.len(), 128 * 128);
        assert_eq!(g.column_count, 128);
        assert_eq!(g.pose.and_then(|p| p.position).map(|p| p.x), Some(-6.4));
    }
}
