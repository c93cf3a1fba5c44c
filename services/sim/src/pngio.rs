//! PNG output of rendered pairs and ground truth, and [`render_to_dir`] (backs
//! `hvs sim render --map F --pose x,y,heading_deg --out DIR`).

use std::path::{Path, PathBuf};

use image::{ImageBuffer, Luma};

use crate::defects::{DefectsError, WebcamDefects, sim_rng};
use crate::map::{GridMap, MapError, Pose};
use crate::render::{RenderError, Renderer, StereoRig};

/// Errors of writing or reading a PNG.
#[derive(Debug, thiserror::Error)]
pub enum PngError {
    /// The pixel buffer does not match the size.
    #[error("cannot write {path}: buffer has {got} pixels, expected {width}x{height}")]
    BufferSize {
        /// Target file.
        path: PathBuf,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Buffer length.
        got: usize,
    },
    /// Encoding or writing failed.
    #[error("cannot write PNG {path}: {source}")]
    Write {
        /// Target file.
        path: PathBuf,
        /// Cause.
        source: image::ImageError,
    },
    /// Reading or decoding failed.
    #[error("cannot read PNG {path}: {source}")]
    Read {
        /// Source file.
        path: PathBuf,
        /// Cause.
        source: image::ImageError,
    },
}

fn dims(path: &Path, width: usize, height: usize, got: usize) -> Result<(u32, u32), PngError> {
    let bad = || PngError::BufferSize {
        path: path.to_path_buf(),
        width,
        height,
        got,
    };
    if width.checked_mul(height) != Some(got) {
        return Err(bad());
    }
    Ok((
        u32::try_from(width).map_err(|_| bad())?,
        u32::try_from(height).map_err(|_| bad())?,
    ))
}

/// Writes an 8-bit grey PNG.
pub fn write_gray8(path: &Path, width: usize, height: usize, data: &[u8]) -> Result<(), PngError> {
    let (w, h) = dims(path, width, height, data.len())?;
    let img: ImageBuffer<Luma<u8>, &[u8]> =
        ImageBuffer::from_raw(w, h, data).ok_or_else(|| PngError::BufferSize {
            path: path.to_path_buf(),
            width,
            height,
            got: data.len(),
        })?;
    img.save_with_format(path, image::ImageFormat::Png)
        .map_err(|source| PngError::Write {
            path: path.to_path_buf(),
            source,
        })
}

/// Writes a 16-bit grey PNG.
pub fn write_gray16(
    path: &Path,
    width: usize,
    height: usize,
    data: &[u16],
) -> Result<(), PngError> {
    let (w, h) = dims(path, width, height, data.len())?;
    let img: ImageBuffer<Luma<u16>, &[u16]> =
        ImageBuffer::from_raw(w, h, data).ok_or_else(|| PngError::BufferSize {
            path: path.to_path_buf(),
            width,
            height,
            got: data.len(),
        })?;
    img.save_with_format(path, image::ImageFormat::Png)
        .map_err(|source| PngError::Write {
            path: path.to_path_buf(),
            source,
        })
}

/// Reads a grey PNG as 8-bit (converting if needed); returns (width, height, pixels).
pub fn read_gray8(path: &Path) -> Result<(usize, usize, Vec<u8>), PngError> {
    let img = image::open(path).map_err(|source| PngError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let g = img.into_luma8();
    Ok((g.width() as usize, g.height() as usize, g.into_raw()))
}

/// Reads a grey PNG as 16-bit (converting if needed); returns (width, height, pixels).
pub fn read_gray16(path: &Path) -> Result<(usize, usize, Vec<u16>), PngError> {
    let img = image::open(path).map_err(|source| PngError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let g = img.into_luma16();
    Ok((g.width() as usize, g.height() as usize, g.into_raw()))
}

/// Image size of [`render_to_dir`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RenderSize {
    /// 640x480, f = 640 px.
    Vga,
    /// 320x240, f = 320 px.
    Qvga,
}

impl RenderSize {
    /// The rig for this size.
    pub fn rig(self) -> StereoRig {
        match self {
            RenderSize::Vga => StereoRig::vga(),
            RenderSize::Qvga => StereoRig::qvga(),
        }
    }
}

/// Seed of the noise of [`render_to_dir`] (fixed, so renders are reproducible).
pub const RENDER_TO_DIR_SEED: u64 = 0x5151_2026;

/// Errors of [`render_to_dir`].
#[derive(Debug, thiserror::Error)]
pub enum RenderToDirError {
    /// The map could not be loaded.
    #[error(transparent)]
    Map(#[from] MapError),
    /// The output directory could not be created.
    #[error("cannot create output directory {path}: {source}")]
    OutDir {
        /// The directory.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Rendering failed (e.g. the pose is inside a wall).
    #[error(
        "cannot render {map} at pose x={x_m} m, y={y_m} m, heading {heading_deg} deg: {source}"
    )]
    Render {
        /// Map file.
        map: PathBuf,
        /// Pose x.
        x_m: f64,
        /// Pose y.
        y_m: f64,
        /// Pose heading.
        heading_deg: f64,
        /// Cause.
        source: RenderError,
    },
    /// Applying the webcam defects failed.
    #[error(transparent)]
    Defects(#[from] DefectsError),
    /// Writing an image failed.
    #[error(transparent)]
    Png(#[from] PngError),
}

/// Files written by [`render_to_dir`].
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedFiles {
    /// Left image (8-bit grey).
    pub left_png: PathBuf,
    /// Right image (8-bit grey).
    pub right_png: PathBuf,
    /// Left ground-truth disparity (16-bit grey, disparity x 256, 0 = unknown).
    pub gt_disp_png: PathBuf,
    /// The rig used.
    pub rig: StereoRig,
}

/// Renders the map at `pose` (robot pose; both eyes from the same pose, since a still robot makes
/// the right camera's delay irrelevant) and writes `left.png`, `right.png` and `gt_disp.png` into
/// `out_dir` (created if missing). Defects are applied with the fixed seed
/// [`RENDER_TO_DIR_SEED`].
pub fn render_to_dir(
    map_path: &Path,
    pose: &Pose,
    out_dir: &Path,
    size: RenderSize,
    defects: &WebcamDefects,
) -> Result<RenderedFiles, RenderToDirError> {
    let map = GridMap::load(map_path)?;
    std::fs::create_dir_all(out_dir).map_err(|source| RenderToDirError::OutDir {
        path: out_dir.to_path_buf(),
        source,
    })?;
    let rig = size.rig();
    let renderer = Renderer::new(&map, rig);
    let n = rig.pixels();
    let (mut left, mut right, mut gt) = (vec![0u8; n], vec![0u8; n], vec![0u16; n]);
    renderer
        .render_pair(pose, pose, &mut left, &mut right, Some(&mut gt))
        .map_err(|source| RenderToDirError::Render {
            map: map_path.to_path_buf(),
            x_m: pose.x_m,
            y_m: pose.y_m,
            heading_deg: pose.heading_deg(),
            source,
        })?;
    let mut rng = sim_rng(RENDER_TO_DIR_SEED);
    defects.apply(&mut left, &mut right, rig.width, rig.height, &mut rng)?;
    let files = RenderedFiles {
        left_png: out_dir.join("left.png"),
        right_png: out_dir.join("right.png"),
        gt_disp_png: out_dir.join("gt_disp.png"),
        rig,
    };
    write_gray8(&files.left_png, rig.width, rig.height, &left)?;
    write_gray8(&files.right_png, rig.width, rig.height, &right)?;
    write_gray16(&files.gt_disp_png, rig.width, rig.height, &gt)?;
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAP: &str = "@cell_m 0.5\n#########\n#.......#\n#.>.....#\n#.......#\n#########\n";

    fn map_file(dir: &Path) -> PathBuf {
        let p = dir.join("m.txt");
        std::fs::write(&p, MAP).unwrap();
        p
    }

    #[test]
    fn writes_pngs_that_read_back_as_the_render() {
        let dir = tempfile::tempdir().unwrap();
        let map_path = map_file(dir.path());
        let out = dir.path().join("out/nested");
        let pose = Pose::from_deg(1.2, 1.25, 10.0);
        let files = render_to_dir(
            &map_path,
            &pose,
            &out,
            RenderSize::Qvga,
            &WebcamDefects::none(),
        )
        .unwrap();
        let (w, h, left) = read_gray8(&files.left_png).unwrap();
        assert_eq!((w, h), (320, 240));
        let (_, _, right) = read_gray8(&files.right_png).unwrap();
        let (_, _, gt) = read_gray16(&files.gt_disp_png).unwrap();
        let map = GridMap::parse(MAP, "m").unwrap();
        let rig = StereoRig::qvga();
        let n = rig.pixels();
        let (mut l, mut r, mut g) = (vec![0u8; n], vec![0u8; n], vec![0u16; n]);
        Renderer::new(&map, rig)
            .render_pair(&pose, &pose, &mut l, &mut r, Some(&mut g))
            .unwrap();
        assert_eq!(left, l);
        assert_eq!(right, r);
        assert_eq!(gt, g, "16-bit disparity survives the PNG round trip");
        assert!(gt.iter().any(|&d| d > 255), "uses the 16-bit range");
    }

    #[test]
    fn defects_are_applied() {
        let dir = tempfile::tempdir().unwrap();
        let map_path = map_file(dir.path());
        let pose = Pose::from_deg(1.2, 1.25, 0.0);
        let clean = dir.path().join("clean");
        let noisy = dir.path().join("noisy");
        render_to_dir(
            &map_path,
            &pose,
            &clean,
            RenderSize::Qvga,
            &WebcamDefects::none(),
        )
        .unwrap();
        let defects = WebcamDefects {
            gain: 0.5,
            ..WebcamDefects::none()
        };
        render_to_dir(&map_path, &pose, &noisy, RenderSize::Qvga, &defects).unwrap();
        let (_, _, a) = read_gray8(&clean.join("right.png")).unwrap();
        let (_, _, b) = read_gray8(&noisy.join("right.png")).unwrap();
        let sum = |v: &[u8]| v.iter().map(|&x| u64::from(x)).sum::<u64>();
        let ratio = sum(&b) as f64 / sum(&a) as f64;
        assert!((ratio - 0.5).abs() < 0.01, "{ratio}");
        let (_, _, la) = read_gray8(&clean.join("left.png")).unwrap();
        let (_, _, lb) = read_gray8(&noisy.join("left.png")).unwrap();
        assert_eq!(la, lb);
    }

    #[test]
    fn errors_name_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let map_path = map_file(dir.path());
        let pose = Pose::from_deg(1.2, 1.25, 0.0);
        let none = WebcamDefects::none();
        // Output "directory" below a regular file.
        let blocker = dir.path().join("file");
        std::fs::write(&blocker, b"x").unwrap();
        let e = render_to_dir(
            &map_path,
            &pose,
            &blocker.join("out"),
            RenderSize::Qvga,
            &none,
        )
        .unwrap_err();
        assert!(matches!(e, RenderToDirError::OutDir { .. }), "{e}");
        assert!(e.to_string().contains("file/out"), "{e}");
        // Missing and malformed maps.
        let e = render_to_dir(
            &dir.path().join("nope.txt"),
            &pose,
            dir.path(),
            RenderSize::Qvga,
            &none,
        )
        .unwrap_err();
        assert!(e.to_string().contains("nope.txt"), "{e}");
        let bad = dir.path().join("bad.txt");
        std::fs::write(&bad, "###\n#>?\n###\n").unwrap();
        let e = render_to_dir(&bad, &pose, dir.path(), RenderSize::Qvga, &none).unwrap_err();
        assert!(e.to_string().contains("bad.txt:2:3"), "{e}");
        // A pose inside a wall.
        let e = render_to_dir(
            &map_path,
            &Pose::from_deg(0.1, 0.1, 0.0),
            dir.path(),
            RenderSize::Qvga,
            &none,
        )
        .unwrap_err();
        assert!(matches!(e, RenderToDirError::Render { .. }), "{e}");
        // Wrong buffer size for a PNG.
        let e = write_gray8(&dir.path().join("x.png"), 4, 4, &[0u8; 15]).unwrap_err();
        assert!(e.to_string().contains("x.png"), "{e}");
    }
}
