//! How an hvs sample travels on zenoh: the payload is the contract type's bytes exactly as
//! they lie in shared memory (`docs/ipc.md` gives every layout), LZ4-compressed for images
//! and maps when the config says so; the zenoh encoding names the contract type; a 32-byte
//! attachment carries a magic, the flags, the raw length and the sender's wall-clock time
//! (for the hop latency). Written by hand because it is four fixed fields: a serialisation
//! crate would add a format, not remove code.
//!
//! A receiver checks, in order: attachment and magic, type name, sizes (before any
//! decompression, so a hostile length allocates nothing), the decompressed length, and
//! finally the type's own rules ([`Bridged::check`]).

use bytemuck::Zeroable;

use crate::check::Bridged;

/// The attachment's first four bytes.
pub const MAGIC: [u8; 4] = *b"HVS1";
/// Attachment length.
pub const ATTACHMENT_LEN: usize = 32;
/// Flag: the payload is an LZ4 block.
pub const FLAG_LZ4: u32 = 1;

/// The attachment of one hvs message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Envelope {
    /// [`FLAG_LZ4`] or 0.
    pub flags: u32,
    /// Length of the contract type's bytes (after decompression).
    pub raw_len: u64,
    /// The sender's wall-clock time when it sent, ns since the Unix epoch.
    pub sent_wall_ns: u64,
    /// The sending bridge's counter for this topic.
    pub seq: u64,
}

impl Envelope {
    /// The attachment bytes.
    pub fn to_bytes(&self) -> [u8; ATTACHMENT_LEN] {
        let mut b = [0u8; ATTACHMENT_LEN];
        b[0..4].copy_from_slice(&MAGIC);
        b[4..8].copy_from_slice(&self.flags.to_le_bytes());
        b[8..16].copy_from_slice(&self.raw_len.to_le_bytes());
        b[16..24].copy_from_slice(&self.sent_wall_ns.to_le_bytes());
        b[24..32].copy_from_slice(&self.seq.to_le_bytes());
        b
    }

    /// Parses attachment bytes.
    pub fn parse(b: &[u8]) -> Result<Self, WireError> {
        if b.len() != ATTACHMENT_LEN {
            return Err(WireError::Attachment(format!(
                "{} bytes, expected {ATTACHMENT_LEN}",
                b.len()
            )));
        }
        if b[0..4] != MAGIC {
            return Err(WireError::Attachment("wrong magic".into()));
        }
        let u64_at = |i: usize| {
            let mut a = [0u8; 8];
            a.copy_from_slice(&b[i..i + 8]);
            u64::from_le_bytes(a)
        };
        let mut f = [0u8; 4];
        f.copy_from_slice(&b[4..8]);
        let flags = u32::from_le_bytes(f);
        if flags & !FLAG_LZ4 != 0 {
            return Err(WireError::Attachment(format!("unknown flags {flags:#x}")));
        }
        Ok(Self {
            flags,
            raw_len: u64_at(8),
            sent_wall_ns: u64_at(16),
            seq: u64_at(24),
        })
    }
}

/// Why a received message was dropped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WireError {
    /// No attachment, or not ours.
    #[error("attachment: {0}")]
    Attachment(String),
    /// The encoding names another type.
    #[error("type {got:?}, expected {expected}")]
    WrongType {
        /// What the topic carries.
        expected: &'static str,
        /// What the message says.
        got: String,
    },
    /// A length does not fit the type.
    #[error("size: {0}")]
    Size(String),
    /// The LZ4 block is corrupt.
    #[error("lz4: {0}")]
    Decompress(String),
    /// The value breaks the type's rules.
    #[error("invalid value: {0}")]
    Invalid(String),
}

/// Encodes a sample for the wire: the payload bytes and the attachment (LZ4 when `compress`
/// and the block is smaller than the value).
pub fn encode<T: Bridged>(
    value: &T,
    compress: bool,
    sent_wall_ns: u64,
    seq: u64,
) -> (Vec<u8>, [u8; ATTACHMENT_LEN]) {
    let raw = bytemuck::bytes_of(value);
    // Camera images carry sensor noise and LZ4 rarely shrinks them; a block that does not
    // shrink goes raw, so compression never costs bandwidth.
    let compressed = compress.then(|| lz4_flex::block::compress(raw));
    let (payload, flags) = match compressed {
        Some(c) if c.len() < raw.len() => (c, FLAG_LZ4),
        _ => (raw.to_vec(), 0),
    };
    let env = Envelope {
        flags,
        raw_len: raw.len() as u64,
        sent_wall_ns,
        seq,
    };
    (payload, env.to_bytes())
}

/// The largest LZ4 block of `n` input bytes (the format's worst case).
pub const fn lz4_bound(n: usize) -> usize {
    n + n / 255 + 16
}

/// Decodes and checks a received message into a heap value of the topic's type.
pub fn decode<T: Bridged>(
    type_name: Option<&str>,
    payload: &[u8],
    attachment: Option<&[u8]>,
) -> Result<(Box<T>, Envelope), WireError> {
    let env = Envelope::parse(attachment.ok_or_else(|| WireError::Attachment("missing".into()))?)?;
    match type_name {
        Some(name) if name == T::TYPE_NAME => {}
        other => {
            return Err(WireError::WrongType {
                expected: T::TYPE_NAME,
                got: other.unwrap_or("none").to_string(),
            });
        }
    }
    let size = core::mem::size_of::<T>();
    if env.raw_len != size as u64 {
        return Err(WireError::Size(format!(
            "raw length {} for a {size}-byte {}",
            env.raw_len,
            T::TYPE_NAME
        )));
    }
    let mut value: Box<T> = bytemuck::allocation::zeroed_box();
    let out = bytemuck::bytes_of_mut(&mut *value);
    if env.flags & FLAG_LZ4 != 0 {
        if payload.len() > lz4_bound(size) {
            return Err(WireError::Size(format!(
                "{} compressed bytes for a {size}-byte value",
                payload.len()
            )));
        }
        let n = lz4_flex::block::decompress_into(payload, out)
            .map_err(|e| WireError::Decompress(e.to_string()))?;
        if n != size {
            return Err(WireError::Size(format!(
                "decompressed to {n} of {size} bytes"
            )));
        }
    } else {
        if payload.len() != size {
            return Err(WireError::Size(format!(
                "{} bytes for a {size}-byte {}",
                payload.len(),
                T::TYPE_NAME
            )));
        }
        out.copy_from_slice(payload);
    }
    value.check().map_err(WireError::Invalid)?;
    Ok((value, env))
}

/// A zeroed value of a bridged type on the heap (frames are too big for a thread's stack).
pub fn zeroed<T: Bridged + Zeroable>() -> Box<T> {
    bytemuck::allocation::zeroed_box()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvs_shared::codes::{MotionCommand, StereoAlgorithm};
    use hvs_shared::messages::{Decision, DisparityMap640x480, StereoFrame320x240};

    fn frame() -> Box<StereoFrame320x240> {
        let mut f: Box<StereoFrame320x240> = zeroed();
        f.header.width = 320;
        f.header.height = 240;
        f.header.frame_id = 42;
        f.header.source = hvs_shared::codes::FrameSource::Simulator.code();
        for (i, p) in f.left.iter_mut().enumerate() {
            *p = (i % 251) as u8;
        }
        f
    }

    #[test]
    fn round_trip_raw_and_compressed() {
        let f = frame();
        for compress in [false, true] {
            let (payload, att) = encode(&*f, compress, 7, 1);
            let (back, env) =
                decode::<StereoFrame320x240>(Some("hvs::StereoFrame320x240"), &payload, Some(&att))
                    .expect("decodes");
            assert_eq!(bytemuck::bytes_of(&*back), bytemuck::bytes_of(&*f));
            assert_eq!(env.sent_wall_ns, 7);
            if compress {
                assert!(payload.len() < core::mem::size_of::<StereoFrame320x240>());
            }
        }
    }

    #[test]
    fn every_kind_of_bad_message_is_refused_with_its_reason() {
        let f = frame();
        let (payload, att) = encode(&*f, true, 0, 1);
        let name = Some("hvs::StereoFrame320x240");
        let err =
            |r: Result<(Box<StereoFrame320x240>, Envelope), WireError>| r.expect_err("refused");
        assert!(matches!(
            err(decode(name, &payload, None)),
            WireError::Attachment(_)
        ));
        assert!(matches!(
            err(decode(name, &payload, Some(&att[..10]))),
            WireError::Attachment(_)
        ));
        let mut bad = att;
        bad[0] = b'X';
        assert!(matches!(
            err(decode(name, &payload, Some(&bad))),
            WireError::Attachment(_)
        ));
        assert!(matches!(
            err(decode(Some("hvs::Decision"), &payload, Some(&att))),
            WireError::WrongType { .. }
        ));
        // A length claimed beyond the type, before any decompression.
        let mut long = att;
        long[8..16].copy_from_slice(&(1u64 << 40).to_le_bytes());
        assert!(matches!(
            err(decode(name, &payload, Some(&long))),
            WireError::Size(_)
        ));
        // Oversized compressed payload.
        let huge = vec![0u8; lz4_bound(core::mem::size_of::<StereoFrame320x240>()) + 1];
        assert!(matches!(
            err(decode(name, &huge, Some(&att))),
            WireError::Size(_)
        ));
        // Corrupt LZ4.
        let junk: Vec<u8> = (0..5000u32).map(|i| (i * 7919 % 256) as u8).collect();
        assert!(matches!(
            err(decode(name, &junk, Some(&att))),
            WireError::Decompress(_) | WireError::Size(_)
        ));
        // Truncated raw payload.
        let (raw, raw_att) = encode(&*f, false, 0, 1);
        assert!(matches!(
            err(decode(name, &raw[..100], Some(&raw_att))),
            WireError::Size(_)
        ));
        // Well-formed bytes, invalid value.
        let mut wrong = frame();
        wrong.header.width = 10;
        let (p, a) = encode(&*wrong, false, 0, 1);
        assert!(matches!(
            err(decode(name, &p, Some(&a))),
            WireError::Invalid(_)
        ));
    }

    #[test]
    fn maps_and_commands_are_checked_after_decoding() {
        let mut d: Box<DisparityMap640x480> = zeroed();
        d.header.width = 640;
        d.header.height = 480;
        d.header.min_disp = 4;
        d.header.max_disp = 110;
        d.header.algorithm = StereoAlgorithm::Sgm.code();
        let (p, a) = encode(&*d, true, 0, 1);
        assert!(
            decode::<DisparityMap640x480>(Some("hvs::DisparityMap640x480"), &p, Some(&a)).is_ok()
        );
        let c = Decision {
            command: MotionCommand::Left.code() + 40,
            ..Default::default()
        };
        let (p, a) = encode(&c, false, 0, 1);
        assert!(matches!(
            decode::<Decision>(Some("hvs::Decision"), &p, Some(&a)),
            Err(WireError::Invalid(_))
        ));
    }
}
