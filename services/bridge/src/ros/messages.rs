//! The ROS 2 messages the bridge publishes, CDR-encoded from hvs contract types.

use hvs_shared::codes::MotionCommand;
use hvs_shared::messages::{DISPARITY_SCALE, Decision};

use super::cdr::CdrWriter;

/// A `std_msgs/Header`'s content.
#[derive(Debug, Clone, Copy)]
pub struct Stamp<'a> {
    /// Wall-clock time, ns since the Unix epoch.
    pub wall_ns: u64,
    /// The coordinate frame (`camera`).
    pub frame_id: &'a str,
}

fn header(w: &mut CdrWriter, s: Stamp<'_>) {
    w.i32((s.wall_ns / 1_000_000_000) as i32)
        .u32((s.wall_ns % 1_000_000_000) as u32)
        .string(s.frame_id);
}

fn image_body(w: &mut CdrWriter, s: Stamp<'_>, width: u32, height: u32, encoding: &str, step: u32) {
    header(w, s);
    w.u32(height).u32(width).string(encoding).u8(0).u32(step);
}

/// sensor_msgs/Image, `mono8`, from a grey image.
pub fn mono8_image(s: Stamp<'_>, width: u32, height: u32, grey: &[u8]) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(grey.len() + 64);
    image_body(&mut w, s, width, height, "mono8", width);
    w.bytes(grey);
    w.finish()
}

/// A pinhole camera's intrinsics (rectified images: no distortion).
#[derive(Debug, Clone, Copy)]
pub struct Intrinsics {
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Focal length, px.
    pub focal_px: f64,
    /// Principal point, px.
    pub cx: f64,
    /// Principal point, px.
    pub cy: f64,
}

/// sensor_msgs/CameraInfo of the left camera.
pub fn camera_info(s: Stamp<'_>, c: Intrinsics) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(400);
    header(&mut w, s);
    w.u32(c.height).u32(c.width).string("plumb_bob");
    w.f64_seq(&[0.0; 5]);
    w.f64_array(&[c.focal_px, 0.0, c.cx, 0.0, c.focal_px, c.cy, 0.0, 0.0, 1.0]);
    w.f64_array(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    w.f64_array(&[
        c.focal_px, 0.0, c.cx, 0.0, 0.0, c.focal_px, c.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
    ]);
    w.u32(0).u32(0);
    // RegionOfInterest: whole image, no rectification asked.
    w.u32(0).u32(0).u32(0).u32(0).u8(0);
    w.finish()
}

/// stereo_msgs/DisparityImage (a 32FC1 image, NaN where the matcher found nothing) from an
/// hvs disparity map (u16 in 1/256 px, 0 = none).
#[allow(clippy::too_many_arguments)]
pub fn disparity_image(
    s: Stamp<'_>,
    width: u32,
    height: u32,
    disparity_q8: &[u16],
    focal_px: f32,
    baseline_m: f32,
    min_disp: u32,
    max_disp: u32,
) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(disparity_q8.len() * 4 + 128);
    header(&mut w, s);
    image_body(&mut w, s, width, height, "32FC1", width * 4);
    w.bytes_with(disparity_q8.len() * 4, |out| {
        for (o, &d) in out.chunks_exact_mut(4).zip(disparity_q8) {
            let v = if d == 0 {
                f32::NAN
            } else {
                d as f32 / DISPARITY_SCALE
            };
            o.copy_from_slice(&v.to_le_bytes());
        }
    });
    w.f32(focal_px).f32(baseline_m);
    w.u32(0).u32(0).u32(height).u32(width).u8(0);
    w.f32(min_disp as f32)
        .f32(max_disp as f32)
        .f32(1.0 / DISPARITY_SCALE);
    w.finish()
}

/// The commanded motion of a decision as a velocity, m/s and rad/s: the skid-steer base
/// drives at `forward_speed_mps` and turns in place with its wheels at that speed in
/// opposite directions (`track_m` apart).
pub fn motion(decision: &Decision, forward_speed_mps: f64, track_m: f64) -> (f64, f64) {
    let turn = 2.0 * forward_speed_mps / track_m;
    match MotionCommand::from_code(decision.command) {
        MotionCommand::Forward => (forward_speed_mps, 0.0),
        MotionCommand::Reverse => (-forward_speed_mps, 0.0),
        MotionCommand::Left => (0.0, turn),
        MotionCommand::Right => (0.0, -turn),
        MotionCommand::Stop => (0.0, 0.0),
    }
}

/// geometry_msgs/Twist.
pub fn twist(linear_x_mps: f64, angular_z_rad_s: f64) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(48);
    w.f64(linear_x_mps).f64(0.0).f64(0.0);
    w.f64(0.0).f64(0.0).f64(angular_z_rad_s);
    w.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_layout_is_the_cdr_of_the_message() {
        let s = Stamp {
            wall_ns: 1_700_000_000_123_456_789,
            frame_id: "camera",
        };
        let b = mono8_image(s, 4, 2, &[1, 2, 3, 4, 5, 6, 7, 8]);
        // encapsulation 4, then: sec 4 + nsec 4 + frame_id (4 + 7, pad 1) + h 4 + w 4 +
        // "mono8" (4 + 6) + is_bigendian 1 (pad 1) + step 4 + data (4 + 8).
        assert_eq!(b.len(), 4 + 8 + 12 + 8 + 10 + 2 + 4 + 12);
        assert_eq!(&b[4..8], &1_700_000_000i32.to_le_bytes());
        assert_eq!(&b[b.len() - 8..], &[1, 2, 3, 4, 5, 6, 7, 8]);
        let d = disparity_image(s, 2, 1, &[0, 512], 320.0, 0.06, 2, 55);
        assert!(d.len() > 60);
        let t = twist(0.274, 0.0);
        assert_eq!(t.len(), 4 + 48);
    }

    #[test]
    fn commands_become_velocities() {
        let mut d = Decision {
            command: MotionCommand::Left.code(),
            ..Default::default()
        };
        let (v, w) = motion(&d, 0.3, 0.2);
        assert_eq!(v, 0.0);
        assert!((w - 3.0).abs() < 1e-9);
        d.command = MotionCommand::Reverse.code();
        assert_eq!(motion(&d, 0.3, 0.2), (-0.3, 0.0));
    }
}
