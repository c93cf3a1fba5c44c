//! `[actuator]`: the servo controller link and its pulse table.

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Left/right pulse widths of one motion, in PSC units of 2 us.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PulsePair {
    /// Left wheels.
    pub left: u16,
    /// Right wheels.
    pub right: u16,
}

/// The motion table: pulse widths per motion (reference values measured on the robot).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct PulseTable {
    /// Wheels stopped.
    pub neutral: PulsePair,
    /// Straight ahead.
    pub forward: PulsePair,
    /// Turn left.
    pub left: PulsePair,
    /// Turn right.
    pub right: PulsePair,
    /// Back up.
    pub reverse: PulsePair,
}

impl Default for PulseTable {
    fn default() -> Self {
        Self {
            neutral: PulsePair {
                left: 760,
                right: 758,
            },
            forward: PulsePair {
                left: 720,
                right: 800,
            },
            left: PulsePair {
                left: 920,
                right: 840,
            },
            right: PulsePair {
                left: 600,
                right: 510,
            },
            reverse: PulsePair {
                left: 800,
                right: 716,
            },
        }
    }
}

/// The servo-controller link.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActuatorConfig {
    /// Serial device, e.g. `/dev/ttyUSB0`; `sim` means the simulator's pty for this instance.
    pub device: String,
    /// Baud rate: the PSC speaks 2400 (or 38400).
    pub baud: u32,
    /// Neutral is sent when the newest decision is older than this.
    pub watchdog_ms: u64,
    /// PSC channel of the left wheels.
    pub left_channel: u8,
    /// PSC channel of the right wheels.
    pub right_channel: u8,
    /// Pulse widths per motion.
    pub pulses: PulseTable,
    /// Ask `!SCVER?` when the link opens and require an answer.
    pub link_check: bool,
}

impl Default for ActuatorConfig {
    fn default() -> Self {
        Self {
            device: "sim".into(),
            baud: 2400,
            watchdog_ms: 300,
            left_channel: 1,
            right_channel: 5,
            pulses: PulseTable::default(),
            link_check: true,
        }
    }
}

impl ActuatorConfig {
    /// Checks the section's values; the key of an error is below the section.
    pub fn validate(&self) -> Result<(), Invalid> {
        let a = self;
        if a.device.is_empty() {
            return Err(Invalid::new("device", "must name a serial device or `sim`"));
        }
        if !matches!(a.baud, 2400 | 38400) {
            return Err(Invalid::new(
                "baud",
                format!("= {} is not a PSC rate (2400 or 38400)", a.baud),
            ));
        }
        if !(50..=5000).contains(&a.watchdog_ms) {
            return Err(Invalid::new(
                "watchdog_ms",
                format!("= {} must be in 50..=5000", a.watchdog_ms),
            ));
        }
        for (key, ch) in [
            ("left_channel", a.left_channel),
            ("right_channel", a.right_channel),
        ] {
            if ch > 15 {
                return Err(Invalid::new(
                    key,
                    format!("= {ch} is not a PSC channel (0..=15)"),
                ));
            }
        }
        if a.left_channel == a.right_channel {
            return Err(Invalid::new(
                "right_channel",
                "must differ from left_channel",
            ));
        }
        let p = &a.pulses;
        for (name, pair) in [
            ("neutral", p.neutral),
            ("forward", p.forward),
            ("left", p.left),
            ("right", p.right),
            ("reverse", p.reverse),
        ] {
            for (side, pw) in [("left", pair.left), ("right", pair.right)] {
                if !(250..=1250).contains(&pw) {
                    return Err(Invalid::new(
                        format!("pulses.{name}.{side}"),
                        format!("= {pw} is outside the PSC range 250..=1250"),
                    ));
                }
            }
        }
        Ok(())
    }
}
