//! Writing pairs into the frames the stage publishes: headers, the rectification remap, the
//! 320x240 downscale, replayed pairs. The stage hands in loaned shared-memory samples; the
//! tests hand in frames of their own.

use hvs_shared::messages::{
    FrameHeader, FrameSource, HI_HEIGHT, HI_WIDTH, LO_HEIGHT, LO_WIDTH, StereoFrame320x240,
    StereoFrame640x480, StereoPayload,
};

use crate::calib::StereoRectifier;
use crate::convert::{ConvertError, downscale_2x};
use crate::replay::ReplayPair;

/// Capture times of one pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PairTimes {
    /// Left exposure, CLOCK_MONOTONIC ns.
    pub left_ns: u64,
    /// Right exposure, CLOCK_MONOTONIC ns.
    pub right_ns: u64,
    /// When the stage had the pair, CLOCK_MONOTONIC ns (start of its processing latency).
    pub received_ns: u64,
}

/// Why a pair was not written.
#[derive(Debug)]
pub enum WriteFailure<E> {
    /// The source could not deliver the images.
    Source(E),
    /// Remap or downscale failed (sizes; a bug).
    Convert(ConvertError),
}

impl<E: std::fmt::Display> std::fmt::Display for WriteFailure<E> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Source(e) => e.fmt(f),
            Self::Convert(e) => e.fmt(f),
        }
    }
}

impl<E: std::error::Error + 'static> std::error::Error for WriteFailure<E> {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Source(e) => Some(e),
            Self::Convert(e) => Some(e),
        }
    }
}

/// Writes the pairs of a camera or file source (V4L2, files): numbers them, fills the
/// capture-size images (through the rectification remap if configured) and downscales the
/// 320x240 pair from a 640x480 one. Without a remap the source writes straight into the
/// frames: no buffer between.
#[derive(Debug)]
pub struct PairWriter {
    rectifier: Option<StereoRectifier>,
    raw_left: Vec<u8>,
    raw_right: Vec<u8>,
    source: FrameSource,
    frame_id: u64,
}

impl PairWriter {
    /// A writer for pairs of `width x height` from `source`.
    pub fn new(
        source: FrameSource,
        rectifier: Option<StereoRectifier>,
        (width, height): (u32, u32),
    ) -> Self {
        let raw_len = if rectifier.is_some() {
            width as usize * height as usize
        } else {
            0
        };
        Self {
            rectifier,
            raw_left: vec![0; raw_len],
            raw_right: vec![0; raw_len],
            source,
            frame_id: 0,
        }
    }

    /// The id of the last pair written (0 before the first).
    pub fn frame_id(&self) -> u64 {
        self.frame_id
    }

    /// The header of the current pair at `width x height`, published at `published_ns`.
    pub fn header(
        &self,
        times: PairTimes,
        width: usize,
        height: usize,
        published_ns: u64,
    ) -> FrameHeader {
        FrameHeader {
            frame_id: self.frame_id,
            capture_ns: times.left_ns,
            left_capture_ns: times.left_ns,
            right_capture_ns: times.right_ns,
            skew_ns: times.right_ns as i64 - times.left_ns as i64,
            published_ns,
            width: width as u32,
            height: height as u32,
            source: self.source as u32,
            reserved: 0,
            replay_hi_frame_id: 0,
        }
    }

    /// Fills `left`/`right` (capture size) with `fill`, through the remap if configured.
    fn fill_images<E>(
        &mut self,
        left: &mut [u8],
        right: &mut [u8],
        fill: impl FnOnce(&mut [u8], &mut [u8]) -> Result<(), E>,
    ) -> Result<(), WriteFailure<E>> {
        match &self.rectifier {
            Some(rect) => {
                fill(&mut self.raw_left, &mut self.raw_right).map_err(WriteFailure::Source)?;
                rect.left
                    .apply(&self.raw_left, left)
                    .map_err(WriteFailure::Convert)?;
                rect.right
                    .apply(&self.raw_right, right)
                    .map_err(WriteFailure::Convert)
            }
            None => fill(left, right).map_err(WriteFailure::Source),
        }
    }

    /// Writes the next pair at 640x480 into `hi` and its downscale into `lo`; `fill` writes
    /// the grey images; `clock` (CLOCK_MONOTONIC ns) stamps `published_ns` once they are
    /// written.
    pub fn write_hi<E>(
        &mut self,
        times: PairTimes,
        hi: &mut StereoFrame640x480,
        lo: &mut StereoFrame320x240,
        clock: impl Fn() -> u64,
        fill: impl FnOnce(&mut [u8], &mut [u8]) -> Result<(), E>,
    ) -> Result<(), WriteFailure<E>> {
        self.frame_id += 1;
        self.fill_images(&mut hi.left, &mut hi.right, fill)?;
        downscale_2x(&hi.left, HI_WIDTH, HI_HEIGHT, &mut lo.left).map_err(WriteFailure::Convert)?;
        downscale_2x(&hi.right, HI_WIDTH, HI_HEIGHT, &mut lo.right)
            .map_err(WriteFailure::Convert)?;
        let published_ns = clock();
        hi.header = self.header(times, HI_WIDTH, HI_HEIGHT, published_ns);
        lo.header = self.header(times, LO_WIDTH, LO_HEIGHT, published_ns);
        Ok(())
    }

    /// Writes the next pair of a 320x240 capture into `lo` (`clock` as for
    /// [`Self::write_hi`]).
    pub fn write_lo<E>(
        &mut self,
        times: PairTimes,
        lo: &mut StereoFrame320x240,
        clock: impl Fn() -> u64,
        fill: impl FnOnce(&mut [u8], &mut [u8]) -> Result<(), E>,
    ) -> Result<(), WriteFailure<E>> {
        self.frame_id += 1;
        self.fill_images(&mut lo.left, &mut lo.right, fill)?;
        lo.header = self.header(times, LO_WIDTH, LO_HEIGHT, clock());
        Ok(())
    }
}

/// Writes the simulator's 640x480 camera pair into `hi` (copied once) and its downscale into
/// `lo`, keeping the simulator's header (ids, capture times) with the sizes set and
/// `published_ns` read from `clock` once each image is written.
pub fn write_sim_pair(
    src: &StereoFrame640x480,
    hi: &mut StereoFrame640x480,
    lo: &mut StereoFrame320x240,
    clock: impl Fn() -> u64,
) -> Result<(), ConvertError> {
    let header = |width: usize, height: usize| FrameHeader {
        width: width as u32,
        height: height as u32,
        published_ns: clock(),
        ..src.header
    };
    hi.left.copy_from_slice(&src.left);
    hi.right.copy_from_slice(&src.right);
    hi.header = header(HI_WIDTH, HI_HEIGHT);
    downscale_2x(&src.left, HI_WIDTH, HI_HEIGHT, &mut lo.left)?;
    downscale_2x(&src.right, HI_WIDTH, HI_HEIGHT, &mut lo.right)?;
    lo.header = header(LO_WIDTH, LO_HEIGHT);
    Ok(())
}

/// A recorded pair whose images do not fit the frame they are replayed into.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("frame {frame_id}: recorded images of {recorded} bytes do not fit a {expected}-byte frame")]
pub struct ReplaySizeMismatch {
    /// The recorded frame id.
    pub frame_id: u64,
    /// Bytes of one recorded image.
    pub recorded: usize,
    /// Bytes of one image of the frame.
    pub expected: usize,
}

/// Writes a recorded pair into `out` with its recorded header, its capture times moved by
/// `rebase` (recorded time to now) and `published_ns` read from `clock` once written.
pub fn write_replayed<T: StereoPayload>(
    pair: &ReplayPair,
    out: &mut T,
    rebase: impl Fn(u64) -> u64,
    clock: impl Fn() -> u64,
) -> Result<(), ReplaySizeMismatch> {
    let (header, left, right) = out.parts_mut();
    if left.len() != pair.left.len() || right.len() != pair.right.len() {
        return Err(ReplaySizeMismatch {
            frame_id: pair.header.frame_id,
            recorded: pair.left.len(),
            expected: left.len(),
        });
    }
    left.copy_from_slice(&pair.left);
    right.copy_from_slice(&pair.right);
    *header = FrameHeader {
        capture_ns: rebase(pair.header.capture_ns),
        left_capture_ns: rebase(pair.header.left_capture_ns),
        right_capture_ns: rebase(pair.header.right_capture_ns),
        published_ns: clock(),
        ..pair.header
    };
    Ok(())
}

/// Moves recorded times to now by one offset (every interval stays as recorded): the
/// recording's first time becomes `now_ns`; 0 (no time) stays 0.
pub fn rebase_to(recording_start_ns: u64, now_ns: u64) -> impl Fn(u64) -> u64 + Copy {
    let offset_ns = now_ns as i128 - recording_start_ns as i128;
    move |t: u64| {
        if t == 0 {
            0
        } else {
            (t as i128 + offset_ns).max(0) as u64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bytemuck::Zeroable;

    fn gradient(left: &mut [u8], right: &mut [u8]) -> Result<(), std::io::Error> {
        for (i, (l, r)) in left.iter_mut().zip(right.iter_mut()).enumerate() {
            *l = (i % 251) as u8;
            *r = (i % 241) as u8;
        }
        Ok(())
    }

    fn times() -> PairTimes {
        PairTimes {
            left_ns: 1_000,
            right_ns: 1_250,
            received_ns: 2_000,
        }
    }

    #[test]
    fn a_640x480_pair_is_written_with_its_downscale_and_numbered_headers() {
        let mut w = PairWriter::new(FrameSource::V4l2, None, (640, 480));
        let mut hi = Box::new(StereoFrame640x480::zeroed());
        let mut lo = Box::new(StereoFrame320x240::zeroed());
        w.write_hi(times(), &mut hi, &mut lo, || 3_000, gradient)
            .map_err(|e| e.to_string())
            .expect("written");
        assert_eq!(w.frame_id(), 1);
        assert_eq!(hi.left[1000], (1000 % 251) as u8);
        assert_eq!(hi.right[1000], (1000 % 241) as u8);
        let mut expected = vec![0u8; LO_WIDTH * LO_HEIGHT];
        downscale_2x(&hi.left, HI_WIDTH, HI_HEIGHT, &mut expected).expect("downscale");
        assert_eq!(&lo.left[..], &expected[..]);
        for (h, (wd, ht)) in [(&hi.header, (640, 480)), (&lo.header, (320, 240))] {
            assert_eq!((h.width, h.height), (wd, ht));
            assert_eq!(h.frame_id, 1);
            assert_eq!(h.capture_ns, 1_000);
            assert_eq!(h.skew_ns, 250);
            assert_eq!(h.published_ns, 3_000);
            assert_eq!(h.source, FrameSource::V4l2 as u32);
        }
        w.write_hi(times(), &mut hi, &mut lo, || 4_000, gradient)
            .map_err(|e| e.to_string())
            .expect("written");
        assert_eq!((hi.header.frame_id, lo.header.frame_id), (2, 2));
    }

    #[test]
    fn a_source_that_fails_is_reported_as_the_source_and_the_id_still_advances() {
        let mut w = PairWriter::new(FrameSource::Files, None, (320, 240));
        let mut lo = Box::new(StereoFrame320x240::zeroed());
        let failed = w.write_lo(
            times(),
            &mut lo,
            || 5,
            |_, _| Err(std::io::Error::other("unplugged")),
        );
        assert!(matches!(failed, Err(WriteFailure::Source(ref e)) if e.to_string() == "unplugged"));
        // The id is spent: a lost pair shows as a gap downstream.
        w.write_lo(times(), &mut lo, || 6, gradient)
            .map_err(|e| e.to_string())
            .expect("written");
        assert_eq!(lo.header.frame_id, 2);
        assert_eq!(lo.header.source, FrameSource::Files as u32);
    }

    #[test]
    fn the_sim_pair_keeps_the_simulators_header_with_the_sizes_set() {
        let mut src = Box::new(StereoFrame640x480::zeroed());
        gradient(&mut src.left, &mut src.right).expect("fill");
        src.header.frame_id = 77;
        src.header.capture_ns = 123;
        let mut hi = Box::new(StereoFrame640x480::zeroed());
        let mut lo = Box::new(StereoFrame320x240::zeroed());
        write_sim_pair(&src, &mut hi, &mut lo, || 999).expect("written");
        assert_eq!(&hi.left[..], &src.left[..]);
        assert_eq!((lo.header.frame_id, lo.header.capture_ns), (77, 123));
        assert_eq!(
            (lo.header.width, lo.header.height, lo.header.published_ns),
            (320, 240, 999)
        );
        assert_eq!((hi.header.width, hi.header.height), (640, 480));
    }

    #[test]
    fn a_replayed_pair_keeps_its_recorded_ids_and_a_wrong_size_is_refused() {
        let pair = ReplayPair {
            header: FrameHeader {
                frame_id: 41,
                capture_ns: 5_000,
                left_capture_ns: 5_000,
                right_capture_ns: 5_100,
                replay_hi_frame_id: 40,
                source: FrameSource::Replay as u32,
                ..FrameHeader::default()
            },
            left: vec![7; LO_WIDTH * LO_HEIGHT],
            right: vec![9; LO_WIDTH * LO_HEIGHT],
        };
        let mut lo = Box::new(StereoFrame320x240::zeroed());
        write_replayed(&pair, &mut *lo, rebase_to(5_000, 80_000), || 90_000).expect("fits");
        assert_eq!((lo.left[0], lo.right[LO_WIDTH * LO_HEIGHT - 1]), (7, 9));
        let h = lo.header;
        assert_eq!((h.frame_id, h.replay_hi_frame_id), (41, 40));
        assert_eq!(
            (h.capture_ns, h.right_capture_ns, h.published_ns),
            (80_000, 80_100, 90_000)
        );
        let mut hi = Box::new(StereoFrame640x480::zeroed());
        let err = write_replayed(&pair, &mut *hi, |t| t, || 0).expect_err("a 320x240 pair");
        assert_eq!(err.expected, HI_WIDTH * HI_HEIGHT);
        assert!(err.to_string().contains("frame 41"), "{err}");
    }

    #[test]
    fn recorded_times_move_by_one_offset_and_no_time_stays_none() {
        let rebase = rebase_to(10_000, 1_000_000);
        assert_eq!(rebase(10_000), 1_000_000);
        assert_eq!(rebase(10_500), 1_000_500);
        assert_eq!(rebase(0), 0);
        // Moving back in time never goes below 0.
        let back = rebase_to(1_000_000, 10);
        assert_eq!(back(500), 0);
    }
}
