//! Locking exposure, gain, white balance and the anti-flicker filter to the same values on
//! both cameras (`[capture.v4l2.controls]`): automatic modes off, manual values set, read back.

use hvs_runtime::config::{PowerLine, V4l2Controls};
use nix::errno::Errno;

use super::device::V4l2Device;

/// Control ids (linux/v4l2-controls.h).
pub mod id {
    /// `V4L2_CID_AUTO_WHITE_BALANCE`.
    pub const AUTO_WHITE_BALANCE: u32 = 0x0098_090c;
    /// `V4L2_CID_AUTOGAIN`.
    pub const AUTOGAIN: u32 = 0x0098_0912;
    /// `V4L2_CID_GAIN`.
    pub const GAIN: u32 = 0x0098_0913;
    /// `V4L2_CID_POWER_LINE_FREQUENCY`.
    pub const POWER_LINE_FREQUENCY: u32 = 0x0098_0918;
    /// `V4L2_CID_WHITE_BALANCE_TEMPERATURE`.
    pub const WHITE_BALANCE_TEMPERATURE: u32 = 0x0098_091a;
    /// `V4L2_CID_EXPOSURE_AUTO`.
    pub const EXPOSURE_AUTO: u32 = 0x009a_0901;
    /// `V4L2_CID_EXPOSURE_ABSOLUTE`.
    pub const EXPOSURE_ABSOLUTE: u32 = 0x009a_0902;
    /// `V4L2_EXPOSURE_MANUAL`, a value of `EXPOSURE_AUTO`.
    pub const EXPOSURE_MANUAL: i32 = 1;
}

/// One control to set: an automatic mode to switch off first (with its "off" value), then
/// the value.
struct Lock {
    key: &'static str,
    auto: Option<(u32, i32)>,
    id: u32,
    value: i32,
}

fn locks(c: &V4l2Controls) -> Vec<Lock> {
    let mut v = Vec::new();
    if let Some(e) = c.exposure_100us {
        v.push(Lock {
            key: "exposure_100us",
            auto: Some((id::EXPOSURE_AUTO, id::EXPOSURE_MANUAL)),
            id: id::EXPOSURE_ABSOLUTE,
            value: e,
        });
    }
    if let Some(g) = c.gain {
        v.push(Lock {
            key: "gain",
            auto: Some((id::AUTOGAIN, 0)),
            id: id::GAIN,
            value: g,
        });
    }
    if let Some(k) = c.white_balance_k {
        v.push(Lock {
            key: "white_balance_k",
            auto: Some((id::AUTO_WHITE_BALANCE, 0)),
            id: id::WHITE_BALANCE_TEMPERATURE,
            value: k,
        });
    }
    if let Some(p) = c.power_line {
        v.push(Lock {
            key: "power_line",
            auto: None,
            id: id::POWER_LINE_FREQUENCY,
            value: match p {
                PowerLine::Off => 0,
                PowerLine::Hz50 => 1,
                PowerLine::Hz60 => 2,
            },
        });
    }
    v
}

/// What setting the controls on one camera did: `key = value` read back per control, and
/// a problem per control that could not be set as asked.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ControlReport {
    /// Controls set, with the value read back.
    pub applied: Vec<(&'static str, i32)>,
    /// Controls that could not be set: key and why.
    pub problems: Vec<(&'static str, String)>,
}

/// Sets the configured controls on one camera. Never fails the capture: a camera without a
/// control, or a value outside its range, is reported (and the value clamped into range).
pub fn apply_controls(dev: &mut dyn V4l2Device, controls: &V4l2Controls) -> ControlReport {
    let mut report = ControlReport::default();
    for lock in locks(controls) {
        match apply_one(dev, &lock) {
            Ok((value, note)) => {
                report.applied.push((lock.key, value));
                if let Some(note) = note {
                    report.problems.push((lock.key, note));
                }
            }
            Err(why) => report.problems.push((lock.key, why)),
        }
    }
    report
}

fn apply_one(dev: &mut dyn V4l2Device, lock: &Lock) -> Result<(i32, Option<String>), String> {
    let errno = |what: &str, e: Errno| format!("{what} failed: {e}");
    if let Some((auto_id, off)) = lock.auto
        && dev
            .query_control(auto_id)
            .map_err(|e| errno("VIDIOC_QUERYCTRL", e))?
            .is_some()
    {
        dev.set_control(auto_id, off)
            .map_err(|e| errno("switching the automatic mode off", e))?;
    }
    let info = dev
        .query_control(lock.id)
        .map_err(|e| errno("VIDIOC_QUERYCTRL", e))?
        .ok_or_else(|| "the camera has no such control".to_string())?;
    if info.unusable {
        return Err(format!(
            "{} cannot be set now (disabled or read-only)",
            info.name
        ));
    }
    if info.minimum > info.maximum {
        return Err(format!(
            "{} reports an empty range {}..={}",
            info.name, info.minimum, info.maximum
        ));
    }
    let value = lock.value.clamp(info.minimum, info.maximum);
    let note = (value != lock.value).then(|| {
        format!(
            "{} clamped to {value} (the camera takes {}..={})",
            lock.value, info.minimum, info.maximum
        )
    });
    dev.set_control(lock.id, value)
        .map_err(|e| errno("VIDIOC_S_CTRL", e))?;
    let read_back = dev
        .control(lock.id)
        .map_err(|e| errno("VIDIOC_G_CTRL", e))?;
    Ok((read_back, note))
}
