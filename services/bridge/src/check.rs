//! What an incoming payload must satisfy before it enters shared memory. Every contract type
//! that may cross the bridge says what "well-formed" means for it; a payload that fails is
//! counted and dropped by the caller, never published.

use core::fmt::Debug;

use bytemuck::Pod;
use iceoryx2::prelude::ZeroCopySend;

use hvs_shared::codes::{
    FrameSource, IntersectionType, MotionCommand, NavPolicy, RangeSource, SendReason,
    StereoAlgorithm,
};
use hvs_shared::messages::{
    ActuatorReport, DISPARITY_SCALE, Decision, DisparityHeader, DisparityMap320x240,
    DisparityMap640x480, FrameHeader, MAX_RANGE_WINDOWS, RangeReport, RobotPose, Sequenced,
    StereoFrame320x240, StereoFrame640x480,
};

/// A contract type that may cross the bridge.
pub trait Bridged: Pod + Sequenced + Debug + ZeroCopySend + Send + Sync + 'static {
    /// The contract's type name (`hvs::StereoFrame640x480`): the zenoh encoding's schema.
    const TYPE_NAME: &'static str;
    /// Checks a received value; the error says which field is wrong.
    fn check(&self) -> Result<(), String>;
}

fn finite(name: &str, v: f64) -> Result<(), String> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(format!("{name} = {v} is not finite"))
    }
}

fn unit(name: &str, v: f32) -> Result<(), String> {
    if (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(format!("{name} = {v} is outside [0, 1]"))
    }
}

fn frame_header(h: &FrameHeader, width: usize, height: usize) -> Result<(), String> {
    if (h.width as usize, h.height as usize) != (width, height) {
        return Err(format!(
            "header says {}x{} in a {width}x{height} frame",
            h.width, h.height
        ));
    }
    if FrameSource::from_code(h.source).is_none() {
        return Err(format!("source code {} is unknown", h.source));
    }
    Ok(())
}

macro_rules! bridged_frame {
    ($t:ty, $name:literal) => {
        impl Bridged for $t {
            const TYPE_NAME: &'static str = $name;
            fn check(&self) -> Result<(), String> {
                frame_header(&self.header, <$t>::WIDTH, <$t>::HEIGHT)
            }
        }
    };
}

fn disparity(
    h: &DisparityHeader,
    values: &[u16],
    width: usize,
    height: usize,
) -> Result<(), String> {
    if (h.width as usize, h.height as usize) != (width, height) {
        return Err(format!(
            "header says {}x{} in a {width}x{height} map",
            h.width, h.height
        ));
    }
    if h.min_disp >= h.max_disp || h.max_disp as usize >= width {
        return Err(format!(
            "disparity range {}..{} is not within 0..{width}",
            h.min_disp, h.max_disp
        ));
    }
    if StereoAlgorithm::from_code(h.algorithm).is_none() {
        return Err(format!("algorithm code {} is unknown", h.algorithm));
    }
    if h.valid_px as usize > width * height {
        return Err(format!("valid_px {} exceeds the map", h.valid_px));
    }
    // One pixel of sub-pixel slack above the searched range.
    let limit = ((h.max_disp + 1) as f32 * DISPARITY_SCALE) as u16;
    if let Some(i) = values.iter().position(|&d| d > limit) {
        return Err(format!(
            "pixel {i} has disparity {} px beyond max_disp {}",
            values[i] as f32 / DISPARITY_SCALE,
            h.max_disp
        ));
    }
    Ok(())
}

macro_rules! bridged_disparity {
    ($t:ty, $name:literal) => {
        impl Bridged for $t {
            const TYPE_NAME: &'static str = $name;
            fn check(&self) -> Result<(), String> {
                disparity(&self.header, &self.disparity_q8, <$t>::WIDTH, <$t>::HEIGHT)
            }
        }
    };
}

bridged_frame!(StereoFrame320x240, "hvs::StereoFrame320x240");
bridged_frame!(StereoFrame640x480, "hvs::StereoFrame640x480");
bridged_disparity!(DisparityMap320x240, "hvs::DisparityMap320x240");
bridged_disparity!(DisparityMap640x480, "hvs::DisparityMap640x480");

impl Bridged for RangeReport {
    const TYPE_NAME: &'static str = "hvs::RangeReport";
    fn check(&self) -> Result<(), String> {
        if self.window_count as usize > MAX_RANGE_WINDOWS {
            return Err(format!(
                "window_count {} > {MAX_RANGE_WINDOWS}",
                self.window_count
            ));
        }
        for (i, w) in self.windows.iter().enumerate() {
            for (name, v) in [
                ("range_m", w.range_m),
                ("near_m", w.near_m),
                ("mean_m", w.mean_m),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(format!("windows[{i}].{name} = {v} is not a range"));
                }
            }
            unit(&format!("windows[{i}].confidence"), w.confidence)?;
            if RangeSource::try_from_code(w.source).is_none() {
                return Err(format!("windows[{i}].source code {} is unknown", w.source));
            }
        }
        finite("scan.tan_half_fov", self.scan.tan_half_fov as f64)?;
        if let Some(i) = self.scan.range_m.iter().position(|r| !r.is_finite()) {
            return Err(format!("scan.range_m[{i}] is not finite"));
        }
        Ok(())
    }
}

impl Bridged for Decision {
    const TYPE_NAME: &'static str = "hvs::Decision";
    fn check(&self) -> Result<(), String> {
        if MotionCommand::try_from_code(self.command).is_none() {
            return Err(format!("command code {} is unknown", self.command));
        }
        if IntersectionType::try_from_code(self.intersection).is_none() {
            return Err(format!(
                "intersection code {} is unknown",
                self.intersection
            ));
        }
        if NavPolicy::from_code(self.policy).is_none() {
            return Err(format!("policy code {} is unknown", self.policy));
        }
        unit("wall_left", self.wall_left)?;
        unit("wall_front", self.wall_front)?;
        unit("wall_right", self.wall_right)?;
        if !(self.turn_angle_deg.is_finite() && self.turn_angle_deg.abs() <= 360.0) {
            return Err(format!(
                "turn_angle_deg = {} is not an angle",
                self.turn_angle_deg
            ));
        }
        if self.ramp > 63 {
            return Err(format!("ramp = {} > 63", self.ramp));
        }
        Ok(())
    }
}

impl Bridged for ActuatorReport {
    const TYPE_NAME: &'static str = "hvs::ActuatorReport";
    fn check(&self) -> Result<(), String> {
        if self.byte_count > 16 {
            return Err(format!("byte_count = {} > 16", self.byte_count));
        }
        if MotionCommand::try_from_code(self.command).is_none() {
            return Err(format!("command code {} is unknown", self.command));
        }
        if SendReason::from_code(self.reason).is_none() {
            return Err(format!("reason code {} is unknown", self.reason));
        }
        Ok(())
    }
}

impl Bridged for RobotPose {
    const TYPE_NAME: &'static str = "hvs::RobotPose";
    fn check(&self) -> Result<(), String> {
        finite("x_m", self.x_m)?;
        finite("y_m", self.y_m)?;
        finite("heading_rad", self.heading_rad)?;
        finite("distance_m", self.distance_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable;

    #[test]
    fn well_formed_values_pass_and_each_bad_field_is_named() {
        let mut f = StereoFrame320x240::zeroed();
        f.header.width = 320;
        f.header.height = 240;
        f.header.source = FrameSource::Simulator.code();
        assert!(f.check().is_ok());
        f.header.width = 640;
        assert!(f.check().is_err_and(|e| e.contains("640x240")));

        let mut d = DisparityMap640x480::zeroed();
        d.header.width = 640;
        d.header.height = 480;
        d.header.min_disp = 4;
        d.header.max_disp = 110;
        d.header.algorithm = StereoAlgorithm::Sgm.code();
        d.disparity_q8[5] = 100 * 256;
        assert!(d.check().is_ok());
        d.disparity_q8[7] = u16::MAX;
        assert!(d.check().is_err_and(|e| e.contains("pixel 7")));

        let mut c = Decision {
            command: MotionCommand::Forward.code(),
            policy: NavPolicy::Fuzzy.code(),
            ..Default::default()
        };
        assert!(c.check().is_ok());
        c.command = 99;
        assert!(c.check().is_err_and(|e| e.contains("command")));
        c.command = 1;
        c.wall_left = f32::NAN;
        assert!(c.check().is_err_and(|e| e.contains("wall_left")));

        let mut r = RangeReport::default();
        assert!(r.check().is_ok());
        r.window_count = 9;
        assert!(r.check().is_err());

        let p = RobotPose {
            x_m: f64::INFINITY,
            ..Default::default()
        };
        assert!(p.check().is_err_and(|e| e.contains("x_m")));
    }
}
