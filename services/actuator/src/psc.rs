//! The Parallax Servo Controller (PSC) wire protocol.
//!
//! Position command: `'!' 'S' 'C' C R PW_low PW_high 0x0D` (8 bytes); C channel 0..=15, R ramp
//! 0..=63, PW pulse width in 2 us units, 250..=1250 (0.5 ms .. 2.5 ms), low byte first.

/// The version query; the PSC answers with three ASCII bytes such as `1.4`.
pub const VERSION_QUERY: &[u8; 8] = b"!SCVER?\r";
/// Length of a position command.
pub const COMMAND_LEN: usize = 8;
/// Smallest pulse width the PSC accepts (0.5 ms).
pub const MIN_PULSE: u16 = 250;
/// Largest pulse width the PSC accepts (2.5 ms).
pub const MAX_PULSE: u16 = 1250;
/// Largest ramp value.
pub const MAX_RAMP: u8 = 63;
/// Highest channel number.
pub const MAX_CHANNEL: u8 = 15;

/// A position command that cannot be encoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PscError {
    /// Channel above 15.
    #[error("PSC channel {0} is out of range 0..=15")]
    Channel(u8),
    /// Ramp above 63.
    #[error("PSC ramp {0} is out of range 0..=63")]
    Ramp(u8),
    /// Pulse width outside 250..=1250.
    #[error("PSC pulse width {0} is out of range 250..=1250")]
    Pulse(u16),
}

/// Encodes a position command, rejecting out-of-range fields.
pub fn position_command(channel: u8, ramp: u8, pulse: u16) -> Result<[u8; COMMAND_LEN], PscError> {
    if channel > MAX_CHANNEL {
        return Err(PscError::Channel(channel));
    }
    if ramp > MAX_RAMP {
        return Err(PscError::Ramp(ramp));
    }
    if !(MIN_PULSE..=MAX_PULSE).contains(&pulse) {
        return Err(PscError::Pulse(pulse));
    }
    let [lo, hi] = pulse.to_le_bytes();
    Ok([b'!', b'S', b'C', channel, ramp, lo, hi, b'\r'])
}

/// Time one byte takes on the wire at `baud` with 8N1 framing (10 bits), ns.
pub fn byte_time_ns(baud: u32) -> u64 {
    10_000_000_000 / baud.max(1) as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forward_left_wheel_frame_is_byte_exact() {
        // 720 = 0x02D0: low byte 0xD0 first.
        assert_eq!(
            position_command(1, 0, 720).unwrap(),
            [0x21, 0x53, 0x43, 0x01, 0x00, 0xD0, 0x02, 0x0D]
        );
    }

    #[test]
    fn out_of_range_fields_are_rejected() {
        assert_eq!(position_command(16, 0, 750), Err(PscError::Channel(16)));
        assert_eq!(position_command(0, 64, 750), Err(PscError::Ramp(64)));
        assert_eq!(position_command(0, 0, 249), Err(PscError::Pulse(249)));
        assert_eq!(position_command(0, 0, 1251), Err(PscError::Pulse(1251)));
        assert!(position_command(15, 63, 1250).is_ok());
        assert!(position_command(0, 0, 250).is_ok());
    }

    #[test]
    fn one_command_takes_33_ms_at_2400_baud() {
        let t = byte_time_ns(2400) * COMMAND_LEN as u64;
        assert!((33_000_000..=33_400_000).contains(&t), "{t}");
    }
}
