//! The serial link to the servo controller, through `serialport`: the same code opens the
//! robot's `/dev/ttyUSB0` and the simulator's pseudo-terminal.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serialport::{DataBits, FlowControl, Parity, SerialPort, StopBits, TTYPort};

use crate::psc::VERSION_QUERY;

/// How long the link check waits for the `!SCVER?` answer.
pub const LINK_CHECK_TIMEOUT: Duration = Duration::from_millis(500);

/// Why the link failed.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The device does not exist.
    #[error("serial device {device} does not exist")]
    Missing {
        /// The device.
        device: PathBuf,
    },
    /// The device exists but cannot be opened (permissions, in use by another process).
    #[error("cannot open serial device {device}: {detail}")]
    Open {
        /// The device.
        device: PathBuf,
        /// The OS's reason.
        detail: String,
    },
    /// The controller did not answer the version query.
    #[error(
        "no servo controller answers on {device}: no reply to !SCVER? within {timeout_ms} ms (check power, wiring and baud rate {baud})"
    )]
    Silent {
        /// The device.
        device: PathBuf,
        /// Wait time.
        timeout_ms: u64,
        /// Baud rate tried.
        baud: u32,
    },
    /// Writing failed (the device vanished, for example a USB adapter unplugged).
    #[error("write to {device} failed: {detail}")]
    Write {
        /// The device.
        device: PathBuf,
        /// The OS's reason.
        detail: String,
    },
}

/// An open link.
pub struct PscLink {
    port: TTYPort,
    device: PathBuf,
    firmware: String,
}

impl PscLink {
    /// Opens `device` at `baud` 8N1 without flow control and, with `check`, asks the controller
    /// for its firmware version. `exclusive` takes the device for this process alone.
    pub fn open(device: &Path, baud: u32, check: bool, exclusive: bool) -> Result<Self, LinkError> {
        if !device.exists() {
            return Err(LinkError::Missing {
                device: device.to_path_buf(),
            });
        }
        let port = serialport::new(device.to_string_lossy(), baud)
            .data_bits(DataBits::Eight)
            .parity(Parity::None)
            .stop_bits(StopBits::One)
            .flow_control(FlowControl::None)
            .timeout(Duration::from_millis(20))
            .exclusive(exclusive)
            .open_native()
            .map_err(|e| LinkError::Open {
                device: device.to_path_buf(),
                detail: e.to_string(),
            })?;
        let mut link = Self {
            port,
            device: device.to_path_buf(),
            firmware: String::new(),
        };
        if check {
            link.firmware = link.query_version(baud)?;
        }
        Ok(link)
    }

    fn query_version(&mut self, baud: u32) -> Result<String, LinkError> {
        // Discard anything stale, then ask.
        let _ = self.port.clear(serialport::ClearBuffer::Input);
        self.write(VERSION_QUERY)?;
        let deadline = Instant::now() + LINK_CHECK_TIMEOUT;
        let mut reply = Vec::new();
        let mut buf = [0u8; 16];
        while reply.len() < 3 && Instant::now() < deadline {
            match self.port.read(&mut buf) {
                Ok(n) => reply.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    return Err(LinkError::Write {
                        device: self.device.clone(),
                        detail: format!("reading the version reply: {e}"),
                    });
                }
            }
        }
        if reply.len() < 3 {
            return Err(LinkError::Silent {
                device: self.device.clone(),
                timeout_ms: LINK_CHECK_TIMEOUT.as_millis() as u64,
                baud,
            });
        }
        Ok(String::from_utf8_lossy(&reply[..3]).into_owned())
    }

    /// Firmware version reported by the link check (empty without a check).
    pub fn firmware(&self) -> &str {
        &self.firmware
    }

    /// The device path.
    pub fn device(&self) -> &Path {
        &self.device
    }

    /// Hands `bytes` to the serial driver (returns before they are on the wire).
    pub fn write(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.port.write_all(bytes).map_err(|e| LinkError::Write {
            device: self.device.clone(),
            detail: e.to_string(),
        })
    }

    /// Blocks until everything written is on the wire (used before exiting).
    pub fn drain(&mut self) {
        let _ = self.port.flush();
    }
}
