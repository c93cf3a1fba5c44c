//! The files source: a folder of left/right PNG pairs, played in name order.
//!
//! Accepted layouts (the first that finds pairs wins):
//! 1. `FOLDER/left/NAME.png` + `FOLDER/right/NAME.png` (same `NAME` in both subfolders);
//! 2. `FOLDER/NAME_left.png` + `FOLDER/NAME_right.png` (also `NAME-left.png`/`NAME-right.png`).
//!
//! Pairs are sorted by `NAME` (byte order: use zero-padded numbers). A left image without its
//! right partner (or the reverse) is an error naming the file. Images are decoded as they are
//! played, converted to 8-bit grey (luma of RGB, 16-bit samples scaled), and must have the
//! capture size.

use std::path::{Path, PathBuf};

/// Why the folder or one of its images could not be used. Every message names the path.
#[derive(Debug, thiserror::Error)]
pub enum FilesError {
    /// The folder (or one of its subfolders) could not be listed.
    #[error("cannot list {folder}: {source}")]
    List {
        /// The folder.
        folder: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// No pairs in either layout.
    #[error(
        "{folder} holds no stereo pairs (expected left/NAME.png + right/NAME.png, or \
         NAME_left.png + NAME_right.png)"
    )]
    Empty {
        /// The folder.
        folder: PathBuf,
    },
    /// One image of a pair has no partner.
    #[error("{file} has no partner: {missing} does not exist")]
    Unpaired {
        /// The image found.
        file: PathBuf,
        /// The partner that was expected.
        missing: PathBuf,
    },
    /// An image could not be read or decoded.
    #[error("cannot decode {file}: {message}")]
    Decode {
        /// The image.
        file: PathBuf,
        /// The decoder's message.
        message: String,
    },
    /// An image has another size than the capture.
    #[error(
        "{file} is {width}x{height}, expected {expected_width}x{expected_height} (capture.width/height)"
    )]
    Size {
        /// The image.
        file: PathBuf,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// The capture width.
        expected_width: u32,
        /// The capture height.
        expected_height: u32,
    },
}

/// One left/right pair of files.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FilePair {
    /// The pair's name (sort key).
    pub name: String,
    /// The left image.
    pub left: PathBuf,
    /// The right image.
    pub right: PathBuf,
}

fn list(folder: &Path) -> Result<Vec<PathBuf>, FilesError> {
    let entries = std::fs::read_dir(folder).map_err(|source| FilesError::List {
        folder: folder.to_path_buf(),
        source,
    })?;
    let mut out = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|source| FilesError::List {
            folder: folder.to_path_buf(),
            source,
        })?;
        out.push(entry.path());
    }
    Ok(out)
}

fn png_stem(path: &Path) -> Option<&str> {
    let name = path.file_name()?.to_str()?;
    let lower = name.to_ascii_lowercase();
    lower.ends_with(".png").then(|| &name[..name.len() - 4])
}

/// Finds the pairs in `folder` (see the module documentation), sorted by name.
pub fn scan_folder(folder: &Path) -> Result<Vec<FilePair>, FilesError> {
    let left_dir = folder.join("left");
    let right_dir = folder.join("right");
    let mut pairs = Vec::new();
    if left_dir.is_dir() && right_dir.is_dir() {
        for (dir, other_dir, is_left) in [
            (&left_dir, &right_dir, true),
            (&right_dir, &left_dir, false),
        ] {
            for path in list(dir)? {
                let Some(stem) = png_stem(&path) else {
                    continue;
                };
                let file_name = path
                    .file_name()
                    .map(|n| n.to_os_string())
                    .unwrap_or_default();
                let partner = other_dir.join(&file_name);
                if !partner.is_file() {
                    return Err(FilesError::Unpaired {
                        file: path,
                        missing: partner,
                    });
                }
                if is_left {
                    pairs.push(FilePair {
                        name: stem.to_string(),
                        left: path.clone(),
                        right: partner,
                    });
                }
            }
        }
    } else {
        for path in list(folder)? {
            let Some(stem) = png_stem(&path) else {
                continue;
            };
            for (suffix, partner_suffix, is_left) in [
                ("_left", "_right", true),
                ("-left", "-right", true),
                ("_right", "_left", false),
                ("-right", "-left", false),
            ] {
                let Some(name) = stem.strip_suffix(suffix) else {
                    continue;
                };
                let ext = path.extension().unwrap_or_default().to_string_lossy();
                let partner = folder.join(format!("{name}{partner_suffix}.{ext}"));
                if !partner.is_file() {
                    return Err(FilesError::Unpaired {
                        file: path.clone(),
                        missing: partner,
                    });
                }
                if is_left {
                    pairs.push(FilePair {
                        name: name.to_string(),
                        left: path.clone(),
                        right: partner,
                    });
                }
                break;
            }
        }
    }
    if pairs.is_empty() {
        return Err(FilesError::Empty {
            folder: folder.to_path_buf(),
        });
    }
    pairs.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(pairs)
}

/// Decodes a PNG to 8-bit grey into `dst`, which must be `width x height`; a file of another
/// size is an error naming it.
pub fn load_grey(file: &Path, width: u32, height: u32, dst: &mut [u8]) -> Result<(), FilesError> {
    let decode_error = |e: image::ImageError| FilesError::Decode {
        file: file.to_path_buf(),
        message: e.to_string(),
    };
    let img = image::ImageReader::open(file)
        .map_err(|e| FilesError::Decode {
            file: file.to_path_buf(),
            message: e.to_string(),
        })?
        .with_guessed_format()
        .map_err(|e| FilesError::Decode {
            file: file.to_path_buf(),
            message: e.to_string(),
        })?
        .decode()
        .map_err(decode_error)?;
    if img.width() != width || img.height() != height {
        return Err(FilesError::Size {
            file: file.to_path_buf(),
            width: img.width(),
            height: img.height(),
            expected_width: width,
            expected_height: height,
        });
    }
    let grey = match img {
        image::DynamicImage::ImageLuma8(g) => g,
        other => other.to_luma8(),
    };
    if dst.len() != grey.as_raw().len() {
        return Err(FilesError::Decode {
            file: file.to_path_buf(),
            message: format!(
                "destination holds {} bytes, expected {}",
                dst.len(),
                grey.as_raw().len()
            ),
        });
    }
    dst.copy_from_slice(grey.as_raw());
    Ok(())
}

/// Plays the pairs of a folder in order, optionally looping.
#[derive(Debug)]
pub struct FileSource {
    pairs: Vec<FilePair>,
    next: usize,
    looping: bool,
    width: u32,
    height: u32,
}

impl FileSource {
    /// Scans `folder` for pairs to play at `width x height` and checks every image's size
    /// from its header (a wrong size is an error naming the file).
    pub fn open(folder: &Path, width: u32, height: u32, looping: bool) -> Result<Self, FilesError> {
        let pairs = scan_folder(folder)?;
        for file in pairs.iter().flat_map(|p| [&p.left, &p.right]) {
            let (w, h) = image::image_dimensions(file).map_err(|e| FilesError::Decode {
                file: file.clone(),
                message: e.to_string(),
            })?;
            if (w, h) != (width, height) {
                return Err(FilesError::Size {
                    file: file.clone(),
                    width: w,
                    height: h,
                    expected_width: width,
                    expected_height: height,
                });
            }
        }
        Ok(Self {
            pairs,
            next: 0,
            looping,
            width,
            height,
        })
    }

    /// The pairs found.
    pub fn pairs(&self) -> &[FilePair] {
        &self.pairs
    }

    /// The next pair to play, or `None` at the end (never when looping).
    pub fn next_pair(&mut self) -> Option<&FilePair> {
        if self.next >= self.pairs.len() {
            if !self.looping {
                return None;
            }
            self.next = 0;
        }
        self.next += 1;
        self.pairs.get(self.next - 1)
    }

    /// Decodes a pair into `left` and `right` (capture size each).
    pub fn load(
        &self,
        pair: &FilePair,
        left: &mut [u8],
        right: &mut [u8],
    ) -> Result<(), FilesError> {
        load_grey(&pair.left, self.width, self.height, left)?;
        load_grey(&pair.right, self.width, self.height, right)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_png(path: &Path, width: u32, height: u32, value: u8) {
        let img = image::GrayImage::from_fn(width, height, |x, y| {
            image::Luma([value.wrapping_add((x + y) as u8)])
        });
        img.save(path).unwrap();
    }

    #[test]
    fn suffix_layout_is_played_in_name_order_and_loops() {
        let dir = tempfile::tempdir().unwrap();
        for (i, name) in ["002", "000", "001"].iter().enumerate() {
            write_png(
                &dir.path().join(format!("{name}_left.png")),
                8,
                6,
                i as u8 * 10,
            );
            write_png(
                &dir.path().join(format!("{name}_right.png")),
                8,
                6,
                i as u8 * 10 + 1,
            );
        }
        std::fs::write(dir.path().join("notes.txt"), "ignored").unwrap();
        let mut src = FileSource::open(dir.path(), 8, 6, true).unwrap();
        let names: Vec<_> = src.pairs().iter().map(|p| p.name.clone()).collect();
        assert_eq!(names, ["000", "001", "002"]);
        let mut seen = Vec::new();
        for _ in 0..4 {
            seen.push(src.next_pair().unwrap().name.clone());
        }
        assert_eq!(seen, ["000", "001", "002", "000"]);
        let pair = src.pairs()[0].clone();
        let (mut l, mut r) = (vec![0u8; 48], vec![0u8; 48]);
        src.load(&pair, &mut l, &mut r).unwrap();
        // "000" was written with i = 1: left value 10, right 11, plus x + y.
        assert_eq!((l[0], r[0], l[9]), (10, 11, 12));
    }

    #[test]
    fn subfolder_layout_is_found_and_stops_without_loop() {
        let dir = tempfile::tempdir().unwrap();
        for side in ["left", "right"] {
            std::fs::create_dir(dir.path().join(side)).unwrap();
            for n in 0..2 {
                write_png(&dir.path().join(side).join(format!("{n:04}.png")), 4, 2, 0);
            }
        }
        let mut src = FileSource::open(dir.path(), 4, 2, false).unwrap();
        assert_eq!(src.pairs().len(), 2);
        assert_eq!(src.pairs()[1].right, dir.path().join("right/0001.png"));
        assert!(src.next_pair().is_some());
        assert!(src.next_pair().is_some());
        assert!(src.next_pair().is_none());
    }

    #[test]
    fn wrong_size_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        write_png(&dir.path().join("a_left.png"), 8, 6, 0);
        write_png(&dir.path().join("a_right.png"), 6, 6, 0);
        let err = FileSource::open(dir.path(), 8, 6, false)
            .unwrap_err()
            .to_string();
        assert!(err.contains("a_right.png is 6x6, expected 8x6"), "{err}");
        // Loading checks too (a file replaced after the scan).
        let pair = scan_folder(dir.path()).unwrap()[0].clone();
        let err = load_grey(&pair.right, 8, 6, &mut [0u8; 48])
            .unwrap_err()
            .to_string();
        assert!(err.contains("a_right.png is 6x6, expected 8x6"), "{err}");
    }

    #[test]
    fn folder_problems_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let err = FileSource::open(dir.path(), 8, 6, false)
            .unwrap_err()
            .to_string();
        assert!(err.contains("holds no stereo pairs"), "{err}");
        write_png(&dir.path().join("x_left.png"), 8, 6, 0);
        let err = FileSource::open(dir.path(), 8, 6, false)
            .unwrap_err()
            .to_string();
        assert!(err.contains("x_left.png has no partner"), "{err}");
        assert!(err.contains("x_right.png"), "{err}");
        std::fs::write(dir.path().join("x_right.png"), b"not a png").unwrap();
        let err = FileSource::open(dir.path(), 8, 6, false)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("cannot decode") && err.contains("x_right.png"),
            "{err}"
        );
        let err = FileSource::open(&dir.path().join("nope"), 8, 6, false)
            .unwrap_err()
            .to_string();
        assert!(err.contains("cannot list") && err.contains("nope"), "{err}");
    }
}
