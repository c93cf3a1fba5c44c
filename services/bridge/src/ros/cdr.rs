//! A little-endian CDR (XCDR1) writer for the few fixed ROS 2 message types the bridge
//! publishes. Written by hand because the messages are five flat structs and the images are
//! hundreds of kilobytes: one `extend_from_slice` per image, no serde pass over every byte.
//! Alignment counts from the byte after the 4-byte encapsulation header, as Fast-CDR (what
//! rmw_zenoh uses) does; the tests decode the output with rosbags, an independent reader.

/// The encapsulation header of plain little-endian CDR.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// A CDR message under construction.
#[derive(Debug)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl CdrWriter {
    /// A message with room for `capacity` bytes after the header.
    pub fn with_capacity(capacity: usize) -> Self {
        let mut buf = Vec::with_capacity(capacity + 4);
        buf.extend_from_slice(&CDR_LE_HEADER);
        Self { buf }
    }

    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - 4;
        let pad = (n - pos % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    /// A `uint8` or `bool`.
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.buf.push(v);
        self
    }

    /// A `uint32`.
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `float32`.
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `string`: length with the terminating NUL, the bytes, the NUL.
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        self
    }

    /// A `uint8[]`: the length, the bytes.
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u32(b.len() as u32);
        self.buf.extend_from_slice(b);
        self
    }

    /// A `uint8[]` of `len` bytes filled in place by `fill` (no intermediate buffer).
    pub fn bytes_with(&mut self, len: usize, fill: impl FnOnce(&mut [u8])) -> &mut Self {
        self.u32(len as u32);
        let start = self.buf.len();
        self.buf.resize(start + len, 0);
        fill(&mut self.buf[start..]);
        self
    }

    /// A `float64[]`.
    pub fn f64_seq(&mut self, v: &[f64]) -> &mut Self {
        self.u32(v.len() as u32);
        for x in v {
            self.f64(*x);
        }
        self
    }

    /// A `float64[N]` (fixed size: no length).
    pub fn f64_array(&mut self, v: &[f64]) -> &mut Self {
        for x in v {
            self.f64(*x);
        }
        self
    }

    /// The finished message.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alignment_counts_from_after_the_header() {
        let mut w = CdrWriter::with_capacity(32);
        w.u8(1).f64(2.0).string("ab").u32(7);
        let b = w.finish();
        assert_eq!(&b[..4], &CDR_LE_HEADER);
        // u8 at 0, pad to 8, f64 at 8..16, string length at 16, "ab\0" at 20..23, pad, u32 at 24.
        assert_eq!(b[4], 1);
        assert_eq!(&b[12..20], &2.0f64.to_le_bytes());
        assert_eq!(&b[20..24], &3u32.to_le_bytes());
        assert_eq!(&b[24..27], b"ab\0");
        assert_eq!(&b[28..32], &7u32.to_le_bytes());
        assert_eq!(b.len(), 32);
    }
}
