//! Stereo calibration files (OpenCV `cv::FileStorage` YAML) and the rectification remap.
//!
//! Accepted: the `%YAML:1.0` files OpenCV writes, with `!!opencv-matrix` nodes (`rows`,
//! `cols`, `dt`, `data`, the data list possibly over several lines). Keys: `K1` (or `M1`),
//! `D1`, `K2` (or `M2`), `D2`, `R` (3x3, or a 3x1 rotation vector), `T`, and optionally all
//! four of `R1`, `R2`, `P1`, `P2`; optionally the calibrated image size as `image_width` +
//! `image_height` or `imageSize: [ w, h ]` (the matrices are then scaled to the capture size).
//! Distortion: 4, 5 or 8 coefficients (`k1 k2 p1 p2 [k3 [k4 k5 k6]]`); 12 or 14 are accepted
//! when the extra (thin prism, tilt) terms are zero. Other keys are ignored.
//!
//! Without `R1`..`P2` the rectification is computed the way `cv::stereoRectify` does with
//! `alpha = -1` and `CALIB_ZERO_DISPARITY`, simplified: both cameras are rotated half-way
//! towards each other and then so that the baseline is the x axis (Bouguet); the new focal
//! length is the smaller `fy` (reduced for barrel distortion as OpenCV does); the new principal
//! point, shared by both cameras, is the mean of the points that centre each camera's
//! undistorted, rotated image corners. Only horizontal rigs (|Tx| > |Ty|) are supported.
//!
//! The remap table stores, for every output pixel, the source position in 1/32 px; pixels are
//! interpolated bilinearly and positions outside the source image come out black (0).

use std::path::{Path, PathBuf};

use crate::convert::ConvertError;

/// Why a calibration file could not be used. Every message names the file, and the key when
/// one is at fault.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    /// The file could not be read.
    #[error("cannot read calibration file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The text is not the FileStorage YAML subset this loader reads.
    #[error("calibration file {path}, line {line}: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A required key is absent.
    #[error("calibration file {path} has no `{key}`")]
    MissingKey {
        /// The file.
        path: PathBuf,
        /// The key (with its alternative name, if any).
        key: String,
    },
    /// A key's value is malformed or unusable.
    #[error("calibration file {path}: `{key}` {message}")]
    Value {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The calibration does not fit the capture size.
    #[error("calibration file {path}: {message}")]
    Size {
        /// The file.
        path: PathBuf,
        /// What does not fit.
        message: String,
    },
}

/// A parsed value.
#[derive(Debug, Clone, PartialEq)]
enum Value {
    Scalar(String),
    Seq(Vec<String>),
    Matrix {
        rows: usize,
        cols: usize,
        data: Vec<f64>,
    },
    Nested,
}

#[derive(Debug, Clone)]
struct Entry {
    key: String,
    line: usize,
    value: Value,
}

/// A dense row-major matrix from the file.
#[derive(Debug, Clone, PartialEq)]
pub struct Matrix {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Row-major values.
    pub data: Vec<f64>,
}

/// The rectifying rotations and projections of both cameras (OpenCV's R1, R2, P1, P2).
#[derive(Debug, Clone, PartialEq)]
pub struct Rectification {
    /// Rotation of the left camera into the rectified frame, row-major 3x3.
    pub r1: [f64; 9],
    /// Rotation of the right camera, row-major 3x3.
    pub r2: [f64; 9],
    /// Projection of the left rectified camera, row-major 3x4.
    pub p1: [f64; 12],
    /// Projection of the right rectified camera, row-major 3x4.
    pub p2: [f64; 12],
}

/// A stereo calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct StereoCalibration {
    /// The file it came from.
    pub path: PathBuf,
    /// Left camera matrix, row-major 3x3.
    pub k1: [f64; 9],
    /// Left distortion `k1 k2 p1 p2 k3 k4 k5 k6` (missing terms zero).
    pub d1: [f64; 8],
    /// Right camera matrix.
    pub k2: [f64; 9],
    /// Right distortion.
    pub d2: [f64; 8],
    /// Rotation from the left to the right camera, row-major 3x3.
    pub r: [f64; 9],
    /// Translation from the left to the right camera (calibration units, e.g. mm).
    pub t: [f64; 3],
    /// R1, R2, P1, P2 if the file has them.
    pub rectification: Option<Rectification>,
    /// The calibrated image size, if the file states it.
    pub image_size: Option<(u32, u32)>,
}

fn syntax(path: &Path, line: usize, message: impl Into<String>) -> CalibrationError {
    CalibrationError::Syntax {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

fn split_key(line: &str) -> Option<(&str, &str)> {
    let (key, rest) = line.split_once(':')?;
    Some((key.trim(), rest.trim()))
}

/// Reads a `[ ... ]` list starting in `first` and continuing over the next lines.
fn read_list<'a>(
    path: &Path,
    first: &str,
    line_no: usize,
    lines: &mut impl Iterator<Item = (usize, &'a str)>,
) -> Result<Vec<String>, CalibrationError> {
    let mut text = first.trim_start_matches('[').to_string();
    while !text.contains(']') {
        match lines.next() {
            Some((_, more)) => {
                text.push(' ');
                text.push_str(strip_comment(more));
            }
            None => return Err(syntax(path, line_no, "list is not closed with `]`")),
        }
    }
    let (inside, after) = text.split_once(']').unwrap_or((&text, ""));
    if !after.trim().is_empty() {
        return Err(syntax(
            path,
            line_no,
            format!("unexpected `{}` after `]`", after.trim()),
        ));
    }
    Ok(inside
        .split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect())
}

fn strip_comment(line: &str) -> &str {
    match line.find('#') {
        Some(i) => &line[..i],
        None => line,
    }
}

fn parse_entries(text: &str, path: &Path) -> Result<Vec<Entry>, CalibrationError> {
    let mut entries = Vec::new();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l)).peekable();
    while let Some((line_no, raw)) = lines.next() {
        let line = strip_comment(raw);
        if line.trim().is_empty()
            || line.starts_with('%')
            || line.trim() == "---"
            || line.trim() == "..."
        {
            continue;
        }
        if line.starts_with([' ', '\t']) {
            // Content of a nested node this loader does not use.
            continue;
        }
        let (key, rest) = split_key(line).ok_or_else(|| {
            syntax(
                path,
                line_no,
                format!("expected `key: value`, found `{}`", line.trim()),
            )
        })?;
        let value = if let Some(tag) = rest.strip_prefix("!!") {
            if tag.trim() != "opencv-matrix" {
                return Err(syntax(
                    path,
                    line_no,
                    format!("`{key}`: unsupported type `!!{}`", tag.trim()),
                ));
            }
            let (mut rows, mut cols, mut dt, mut data) = (None, None, None, None);
            while let Some(&(field_no, field_raw)) = lines.peek() {
                let field = strip_comment(field_raw);
                if !field.starts_with([' ', '\t']) && !field.trim().is_empty() {
                    break;
                }
                lines.next();
                if field.trim().is_empty() {
                    continue;
                }
                let (name, v) = split_key(field).ok_or_else(|| {
                    syntax(
                        path,
                        field_no,
                        format!("`{key}`: expected `field: value`, found `{}`", field.trim()),
                    )
                })?;
                match name {
                    "rows" | "cols" => {
                        let n: usize = v.parse().map_err(|_| CalibrationError::Value {
                            path: path.to_path_buf(),
                            key: key.to_string(),
                            message: format!("has {name} = `{v}`, not a count"),
                        })?;
                        if name == "rows" {
                            rows = Some(n);
                        } else {
                            cols = Some(n);
                        }
                    }
                    "dt" => dt = Some(v.to_string()),
                    "data" => {
                        if !v.starts_with('[') {
                            return Err(syntax(
                                path,
                                field_no,
                                format!("`{key}`: data must be a `[ ... ]` list"),
                            ));
                        }
                        let items = read_list(path, v, field_no, &mut lines)?;
                        let mut values = Vec::with_capacity(items.len());
                        for item in items {
                            let x: f64 = item.parse().map_err(|_| CalibrationError::Value {
                                path: path.to_path_buf(),
                                key: key.to_string(),
                                message: format!("has data value `{item}`, not a number"),
                            })?;
                            if !x.is_finite() {
                                return Err(CalibrationError::Value {
                                    path: path.to_path_buf(),
                                    key: key.to_string(),
                                    message: format!(
                                        "has data value `{item}`, not a finite number"
                                    ),
                                });
                            }
                            values.push(x);
                        }
                        data = Some(values);
                    }
                    other => {
                        return Err(syntax(
                            path,
                            field_no,
                            format!("`{key}`: unknown matrix field `{other}`"),
                        ));
                    }
                }
            }
            let missing = |field: &str| CalibrationError::Value {
                path: path.to_path_buf(),
                key: key.to_string(),
                message: format!("is an opencv-matrix without `{field}`"),
            };
            let rows = rows.ok_or_else(|| missing("rows"))?;
            let cols = cols.ok_or_else(|| missing("cols"))?;
            let dt = dt.ok_or_else(|| missing("dt"))?;
            if !matches!(dt.as_str(), "d" | "f" | "i" | "u" | "s" | "w" | "c") {
                return Err(CalibrationError::Value {
                    path: path.to_path_buf(),
                    key: key.to_string(),
                    message: format!("has dt = `{dt}`; expected one of d f i u s w c"),
                });
            }
            let data = data.ok_or_else(|| missing("data"))?;
            if data.len() != rows * cols {
                return Err(CalibrationError::Value {
                    path: path.to_path_buf(),
                    key: key.to_string(),
                    message: format!(
                        "has {} data values for rows = {rows} x cols = {cols}",
                        data.len()
                    ),
                });
            }
            Value::Matrix { rows, cols, data }
        } else if rest.starts_with('[') {
            Value::Seq(read_list(path, rest, line_no, &mut lines)?)
        } else if rest.is_empty() || rest.starts_with('{') {
            Value::Nested
        } else {
            Value::Scalar(rest.trim_matches('"').to_string())
        };
        entries.push(Entry {
            key: key.to_string(),
            line: line_no,
            value,
        });
    }
    Ok(entries)
}

struct Doc<'a> {
    path: &'a Path,
    entries: Vec<Entry>,
}

impl Doc<'_> {
    fn get(&self, keys: &[&str]) -> Option<&Entry> {
        keys.iter()
            .find_map(|k| self.entries.iter().find(|e| e.key == *k))
    }

    fn value_error(&self, key: &str, message: impl Into<String>) -> CalibrationError {
        CalibrationError::Value {
            path: self.path.to_path_buf(),
            key: key.to_string(),
            message: message.into(),
        }
    }

    fn matrix(&self, keys: &[&str]) -> Result<Option<Matrix>, CalibrationError> {
        let Some(entry) = self.get(keys) else {
            return Ok(None);
        };
        match &entry.value {
            Value::Matrix { rows, cols, data } => Ok(Some(Matrix {
                rows: *rows,
                cols: *cols,
                data: data.clone(),
            })),
            _ => Err(self.value_error(
                &entry.key,
                format!("(line {}) is not an !!opencv-matrix", entry.line),
            )),
        }
    }

    fn required(&self, keys: &[&str]) -> Result<(String, Matrix), CalibrationError> {
        let name = keys.join("` or `");
        let m = self
            .matrix(keys)?
            .ok_or_else(|| CalibrationError::MissingKey {
                path: self.path.to_path_buf(),
                key: name,
            })?;
        let key = self.get(keys).map(|e| e.key.clone()).unwrap_or_default();
        Ok((key, m))
    }

    fn shaped<const N: usize>(
        &self,
        key: &str,
        m: &Matrix,
        shapes: &[(usize, usize)],
    ) -> Result<[f64; N], CalibrationError> {
        if !shapes.contains(&(m.rows, m.cols)) || m.data.len() != N {
            let want: Vec<_> = shapes.iter().map(|(r, c)| format!("{r}x{c}")).collect();
            return Err(self.value_error(
                key,
                format!("is {}x{}, expected {}", m.rows, m.cols, want.join(" or ")),
            ));
        }
        let mut out = [0.0; N];
        out.copy_from_slice(&m.data);
        Ok(out)
    }

    fn camera_matrix(&self, keys: &[&str]) -> Result<[f64; 9], CalibrationError> {
        let (key, m) = self.required(keys)?;
        let k: [f64; 9] = self.shaped(&key, &m, &[(3, 3)])?;
        if !(k[0] > 0.0 && k[4] > 0.0)
            || k[3] != 0.0
            || k[6] != 0.0
            || k[7] != 0.0
            || (k[8] - 1.0).abs() > 1e-9
        {
            return Err(self.value_error(
                &key,
                "is not a camera matrix [fx s cx; 0 fy cy; 0 0 1] with fx, fy > 0",
            ));
        }
        Ok(k)
    }

    fn distortion(&self, keys: &[&str]) -> Result<[f64; 8], CalibrationError> {
        let (key, m) = self.required(keys)?;
        let n = m.data.len();
        if !(m.rows == 1 || m.cols == 1) || !matches!(n, 4 | 5 | 8 | 12 | 14) {
            return Err(self.value_error(
                &key,
                format!(
                    "is {}x{}; expected 4, 5, 8, 12 or 14 coefficients in one row or column",
                    m.rows, m.cols
                ),
            ));
        }
        if m.data.iter().skip(8).any(|&c| c != 0.0) {
            return Err(self.value_error(
                &key,
                "has thin-prism or tilt coefficients (terms 9..14), which are not supported",
            ));
        }
        let mut d = [0.0; 8];
        for (o, v) in d.iter_mut().zip(&m.data) {
            *o = *v;
        }
        Ok(d)
    }

    fn size_value(&self, key: &str) -> Result<Option<u32>, CalibrationError> {
        match self.get(&[key]).map(|e| &e.value) {
            None => Ok(None),
            Some(Value::Scalar(s)) => s
                .parse::<u32>()
                .ok()
                .filter(|&v| v > 0)
                .map(Some)
                .ok_or_else(|| self.value_error(key, format!("= `{s}` is not a positive size"))),
            Some(_) => Err(self.value_error(key, "must be a number")),
        }
    }

    fn image_size(&self) -> Result<Option<(u32, u32)>, CalibrationError> {
        let w = self.size_value("image_width")?;
        let h = self.size_value("image_height")?;
        match (w, h) {
            (Some(w), Some(h)) => return Ok(Some((w, h))),
            (None, None) => {}
            _ => {
                return Err(
                    self.value_error("image_width", "and `image_height` must be given together")
                );
            }
        }
        for key in ["imageSize", "image_size"] {
            if let Some(e) = self.get(&[key]) {
                let parsed = match &e.value {
                    Value::Seq(items) if items.len() == 2 => {
                        match (items[0].parse::<u32>(), items[1].parse::<u32>()) {
                            (Ok(w), Ok(h)) if w > 0 && h > 0 => Some((w, h)),
                            _ => None,
                        }
                    }
                    _ => None,
                };
                return parsed
                    .map(Some)
                    .ok_or_else(|| self.value_error(key, "must be `[ width, height ]`"));
            }
        }
        Ok(None)
    }
}

// Small 3x3 linear algebra on row-major arrays.

fn mat_mul(a: &[f64; 9], b: &[f64; 9]) -> [f64; 9] {
    let mut out = [0.0; 9];
    for r in 0..3 {
        for c in 0..3 {
            out[3 * r + c] = (0..3).map(|k| a[3 * r + k] * b[3 * k + c]).sum();
        }
    }
    out
}

fn transpose(a: &[f64; 9]) -> [f64; 9] {
    [a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8]]
}

fn mat_vec(a: &[f64; 9], v: [f64; 3]) -> [f64; 3] {
    [
        a[0] * v[0] + a[1] * v[1] + a[2] * v[2],
        a[3] * v[0] + a[4] * v[1] + a[5] * v[2],
        a[6] * v[0] + a[7] * v[1] + a[8] * v[2],
    ]
}

/// Rotation matrix of a rotation vector (axis times angle in radians).
pub fn rodrigues_to_matrix(v: [f64; 3]) -> [f64; 9] {
    let theta = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if theta < 1e-12 {
        return [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    }
    let (x, y, z) = (v[0] / theta, v[1] / theta, v[2] / theta);
    let (s, c) = theta.sin_cos();
    let t = 1.0 - c;
    [
        c + x * x * t,
        x * y * t - z * s,
        x * z * t + y * s,
        y * x * t + z * s,
        c + y * y * t,
        y * z * t - x * s,
        z * x * t - y * s,
        z * y * t + x * s,
        c + z * z * t,
    ]
}

/// Rotation vector (axis times angle) of a rotation matrix.
pub fn rodrigues_to_vector(r: &[f64; 9]) -> [f64; 3] {
    let cos = ((r[0] + r[4] + r[8] - 1.0) / 2.0).clamp(-1.0, 1.0);
    let theta = cos.acos();
    let axis = [r[7] - r[5], r[2] - r[6], r[3] - r[1]];
    let s = theta.sin();
    if s > 1e-9 {
        let k = theta / (2.0 * s);
        return [axis[0] * k, axis[1] * k, axis[2] * k];
    }
    if theta < 1e-6 {
        return [0.0; 3];
    }
    // Angle near pi: the axis from the diagonal of (R + I) / 2.
    let xx = ((r[0] + 1.0) / 2.0).max(0.0).sqrt();
    let yy = ((r[4] + 1.0) / 2.0).max(0.0).sqrt().copysign(r[1] + r[3]);
    let zz = ((r[8] + 1.0) / 2.0).max(0.0).sqrt().copysign(r[2] + r[6]);
    [xx * theta, yy * theta, zz * theta]
}

/// Applies distortion `d` (`k1 k2 p1 p2 k3 k4 k5 k6`) to normalised coordinates.
fn distort(d: &[f64; 8], x: f64, y: f64) -> (f64, f64) {
    let r2 = x * x + y * y;
    let radial = (1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4])))
        / (1.0 + r2 * (d[5] + r2 * (d[6] + r2 * d[7])));
    (
        x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x),
        y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y,
    )
}

/// Inverts [`distort`] by fixed-point iteration (as `cv::undistortPoints`).
fn undistort(d: &[f64; 8], xd: f64, yd: f64) -> (f64, f64) {
    let (mut x, mut y) = (xd, yd);
    for _ in 0..20 {
        let r2 = x * x + y * y;
        let icdist = (1.0 + r2 * (d[5] + r2 * (d[6] + r2 * d[7])))
            / (1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4])));
        let dx = 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x);
        let dy = d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y;
        x = (xd - dx) * icdist;
        y = (yd - dy) * icdist;
    }
    (x, y)
}

impl StereoCalibration {
    /// Reads and checks a calibration file.
    pub fn load(path: &Path) -> Result<Self, CalibrationError> {
        let text = std::fs::read_to_string(path).map_err(|source| CalibrationError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses calibration text; `path` is used in messages.
    pub fn parse(text: &str, path: &Path) -> Result<Self, CalibrationError> {
        let doc = Doc {
            path,
            entries: parse_entries(text, path)?,
        };
        let k1 = doc.camera_matrix(&["K1", "M1"])?;
        let d1 = doc.distortion(&["D1"])?;
        let k2 = doc.camera_matrix(&["K2", "M2"])?;
        let d2 = doc.distortion(&["D2"])?;
        let (r_key, r_m) = doc.required(&["R"])?;
        let r = if r_m.data.len() == 3 && (r_m.rows == 1 || r_m.cols == 1) {
            rodrigues_to_matrix([r_m.data[0], r_m.data[1], r_m.data[2]])
        } else {
            let r: [f64; 9] = doc.shaped(&r_key, &r_m, &[(3, 3)])?;
            let should_be_identity = mat_mul(&r, &transpose(&r));
            let off = should_be_identity
                .iter()
                .enumerate()
                .map(|(i, v)| (v - if i % 4 == 0 { 1.0 } else { 0.0 }).abs())
                .fold(0.0, f64::max);
            if off > 1e-3 {
                return Err(doc.value_error(&r_key, "is not a rotation matrix (R R^T != I)"));
            }
            r
        };
        let (t_key, t_m) = doc.required(&["T"])?;
        let t: [f64; 3] = doc.shaped(&t_key, &t_m, &[(3, 1), (1, 3)])?;
        if t[0].abs() <= t[1].abs() {
            return Err(doc.value_error(
                &t_key,
                format!("= {t:?} is not a horizontal baseline (|Tx| must exceed |Ty|)"),
            ));
        }
        let rect_keys = ["R1", "R2", "P1", "P2"];
        let present: Vec<_> = rect_keys
            .iter()
            .filter(|k| doc.get(&[k]).is_some())
            .collect();
        let rectification = if present.is_empty() {
            None
        } else if present.len() < 4 {
            let missing = rect_keys
                .iter()
                .find(|k| doc.get(&[k]).is_none())
                .copied()
                .unwrap_or("R1");
            return Err(doc.value_error(missing, "is missing (R1, R2, P1 and P2 go together)"));
        } else {
            let get = |k: &str| doc.required(&[k]);
            let (_, r1) = get("R1")?;
            let (_, r2) = get("R2")?;
            let (_, p1) = get("P1")?;
            let (_, p2) = get("P2")?;
            let rect = Rectification {
                r1: doc.shaped("R1", &r1, &[(3, 3)])?,
                r2: doc.shaped("R2", &r2, &[(3, 3)])?,
                p1: doc.shaped("P1", &p1, &[(3, 4)])?,
                p2: doc.shaped("P2", &p2, &[(3, 4)])?,
            };
            for (key, p) in [("P1", &rect.p1), ("P2", &rect.p2)] {
                if !(p[0] > 0.0 && p[5] > 0.0) {
                    return Err(
                        doc.value_error(key, "needs positive focal lengths P[0][0], P[1][1]")
                    );
                }
            }
            Some(rect)
        };
        Ok(Self {
            path: path.to_path_buf(),
            k1,
            d1,
            k2,
            d2,
            r,
            t,
            rectification,
            image_size: doc.image_size()?,
        })
    }

    /// The calibration for images of `width x height`: the pixel-unit matrices are scaled when
    /// the file states another image size of the same aspect ratio.
    pub fn for_size(&self, width: u32, height: u32) -> Result<Self, CalibrationError> {
        let Some((cw, ch)) = self.image_size else {
            return Ok(self.clone());
        };
        if (cw, ch) == (width, height) {
            return Ok(self.clone());
        }
        let (sx, sy) = (width as f64 / cw as f64, height as f64 / ch as f64);
        if (sx - sy).abs() > 1e-9 {
            return Err(CalibrationError::Size {
                path: self.path.clone(),
                message: format!(
                    "calibrated at {cw}x{ch}, which does not scale to the capture size {width}x{height}"
                ),
            });
        }
        let mut out = self.clone();
        for k in [&mut out.k1, &mut out.k2] {
            for v in &mut k[..6] {
                *v *= sx;
            }
        }
        if let Some(rect) = &mut out.rectification {
            for p in [&mut rect.p1, &mut rect.p2] {
                for v in &mut p[..8] {
                    *v *= sx;
                }
            }
        }
        out.image_size = Some((width, height));
        Ok(out)
    }

    /// The file's R1, R2, P1, P2, or the computed rectification for `width x height` images
    /// (see the module documentation).
    pub fn rectification(&self, width: u32, height: u32) -> Rectification {
        if let Some(rect) = &self.rectification {
            return rect.clone();
        }
        // Half the rotation to each camera.
        let om = rodrigues_to_vector(&self.r);
        let r_r = rodrigues_to_matrix([-om[0] / 2.0, -om[1] / 2.0, -om[2] / 2.0]);
        let t = mat_vec(&r_r, self.t);
        // Rotate the baseline onto the x axis.
        let uu = [if t[0] > 0.0 { 1.0 } else { -1.0 }, 0.0, 0.0];
        let mut ww = [
            t[1] * uu[2] - t[2] * uu[1],
            t[2] * uu[0] - t[0] * uu[2],
            t[0] * uu[1] - t[1] * uu[0],
        ];
        let nt = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
        let nw = (ww[0] * ww[0] + ww[1] * ww[1] + ww[2] * ww[2]).sqrt();
        if nw > 0.0 {
            let scale = (t[0].abs() / nt).acos() / nw;
            ww = [ww[0] * scale, ww[1] * scale, ww[2] * scale];
        }
        let w_r = rodrigues_to_matrix(ww);
        let r1 = mat_mul(&w_r, &transpose(&r_r));
        let r2 = mat_mul(&w_r, &r_r);
        let t_new = mat_vec(&r2, self.t);

        let (nx, ny) = (width as f64, height as f64);
        let mut fc_new = f64::MAX;
        for (k, d) in [(&self.k1, &self.d1), (&self.k2, &self.d2)] {
            let mut fc = k[4];
            if d[0] < 0.0 {
                fc *= 1.0 + d[0] * (nx * nx + ny * ny) / (4.0 * fc * fc);
            }
            fc_new = fc_new.min(fc);
        }
        let mut cc = [[0.0; 2]; 2];
        for (i, (k, d, rk)) in [(&self.k1, &self.d1, &r1), (&self.k2, &self.d2, &r2)]
            .into_iter()
            .enumerate()
        {
            let mut sum = [0.0; 2];
            for (u, v) in [
                (0.0, 0.0),
                (nx - 1.0, 0.0),
                (0.0, ny - 1.0),
                (nx - 1.0, ny - 1.0),
            ] {
                let yd = (v - k[5]) / k[4];
                let xd = (u - k[2] - k[1] * yd) / k[0];
                let (x, y) = undistort(d, xd, yd);
                let p = mat_vec(rk, [x, y, 1.0]);
                sum[0] += fc_new * p[0] / p[2];
                sum[1] += fc_new * p[1] / p[2];
            }
            cc[i] = [
                (nx - 1.0) / 2.0 - sum[0] / 4.0,
                (ny - 1.0) / 2.0 - sum[1] / 4.0,
            ];
        }
        // CALIB_ZERO_DISPARITY: one principal point for both cameras.
        let c = [(cc[0][0] + cc[1][0]) / 2.0, (cc[0][1] + cc[1][1]) / 2.0];
        let p = |tx: f64| {
            [
                fc_new, 0.0, c[0], tx, 0.0, fc_new, c[1], 0.0, 0.0, 0.0, 1.0, 0.0,
            ]
        };
        Rectification {
            r1,
            r2,
            p1: p(0.0),
            p2: p(t_new[0] * fc_new),
        }
    }
}

/// One output pixel's source: integer position and 1/32 px fractions; `x = u16::MAX` marks a
/// pixel outside the source image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct MapEntry {
    x: u16,
    y: u16,
    fx: u8,
    fy: u8,
}

const INTER_BITS: u32 = 5;
const INTER_SCALE: f64 = (1 << INTER_BITS) as f64;
const OUTSIDE: u16 = u16::MAX;

/// A precomputed remap: for every pixel of the rectified image, where to sample the raw one.
#[derive(Debug, Clone)]
pub struct RemapTable {
    width: usize,
    height: usize,
    entries: Vec<MapEntry>,
}

impl RemapTable {
    /// The table of one camera: camera matrix `k`, distortion `d`, rectifying rotation `r`,
    /// new projection `p` (3x4), for `width x height` images.
    pub fn build(
        k: &[f64; 9],
        d: &[f64; 8],
        r: &[f64; 9],
        p: &[f64; 12],
        width: usize,
        height: usize,
    ) -> Self {
        let rt = transpose(r);
        let mut entries = Vec::with_capacity(width * height);
        for v in 0..height {
            for u in 0..width {
                let x = (u as f64 - p[2]) / p[0];
                let y = (v as f64 - p[6]) / p[5];
                let ray = mat_vec(&rt, [x, y, 1.0]);
                let entry = if ray[2] <= 0.0 {
                    None
                } else {
                    let (xd, yd) = distort(d, ray[0] / ray[2], ray[1] / ray[2]);
                    let su = k[0] * xd + k[1] * yd + k[2];
                    let sv = k[4] * yd + k[5];
                    Self::entry(su, sv, width, height)
                };
                entries.push(entry.unwrap_or(MapEntry {
                    x: OUTSIDE,
                    y: 0,
                    fx: 0,
                    fy: 0,
                }));
            }
        }
        Self {
            width,
            height,
            entries,
        }
    }

    fn entry(su: f64, sv: f64, width: usize, height: usize) -> Option<MapEntry> {
        let xq = (su * INTER_SCALE).round();
        let yq = (sv * INTER_SCALE).round();
        if !(xq.is_finite() && yq.is_finite()) || xq < 0.0 || yq < 0.0 {
            return None;
        }
        let (xq, yq) = (xq as u64, yq as u64);
        let (x, y) = (xq >> INTER_BITS, yq >> INTER_BITS);
        if x as usize >= width || y as usize >= height || x >= OUTSIDE as u64 {
            return None;
        }
        Some(MapEntry {
            x: x as u16,
            y: y as u16,
            fx: (xq & ((1 << INTER_BITS) - 1)) as u8,
            fy: (yq & ((1 << INTER_BITS) - 1)) as u8,
        })
    }

    /// Image width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Where output pixel `(u, v)` samples the source, in px (`None` outside the image).
    pub fn source_of(&self, u: usize, v: usize) -> Option<(f64, f64)> {
        let e = self.entries.get(v * self.width + u)?;
        if e.x == OUTSIDE {
            return None;
        }
        Some((
            e.x as f64 + e.fx as f64 / INTER_SCALE,
            e.y as f64 + e.fy as f64 / INTER_SCALE,
        ))
    }

    /// Whether every pixel samples itself.
    pub fn is_identity(&self) -> bool {
        self.entries.iter().enumerate().all(|(i, e)| {
            e.fx == 0
                && e.fy == 0
                && e.x as usize == i % self.width
                && e.y as usize == i / self.width
        })
    }

    /// Remaps `src` into `dst` (both `width x height`), bilinear, black outside.
    pub fn apply(&self, src: &[u8], dst: &mut [u8]) -> Result<(), ConvertError> {
        let n = self.width * self.height;
        for (what, buf) in [
            ("remap source", src.len()),
            ("remap destination", dst.len()),
        ] {
            if buf != n {
                return Err(ConvertError::BufferSize {
                    what,
                    expected: n,
                    actual: buf,
                    width: self.width,
                    height: self.height,
                });
            }
        }
        let w = self.width;
        let full = 1u32 << INTER_BITS;
        for (out, e) in dst.iter_mut().zip(&self.entries) {
            if e.x == OUTSIDE {
                *out = 0;
                continue;
            }
            let (x0, y0) = (e.x as usize, e.y as usize);
            let x1 = (x0 + 1).min(w - 1);
            let y1 = (y0 + 1).min(self.height - 1);
            let (fx, fy) = (e.fx as u32, e.fy as u32);
            let top = src[y0 * w + x0] as u32 * (full - fx) + src[y0 * w + x1] as u32 * fx;
            let bottom = src[y1 * w + x0] as u32 * (full - fx) + src[y1 * w + x1] as u32 * fx;
            *out = ((top * (full - fy) + bottom * fy + (1 << (2 * INTER_BITS - 1)))
                >> (2 * INTER_BITS)) as u8;
        }
        Ok(())
    }
}

/// The remap tables of both cameras.
#[derive(Debug, Clone)]
pub struct StereoRectifier {
    /// Left camera.
    pub left: RemapTable,
    /// Right camera.
    pub right: RemapTable,
}

impl StereoRectifier {
    /// Builds both tables for `width x height` images (scaling the calibration if it states
    /// another size).
    pub fn new(
        calib: &StereoCalibration,
        width: u32,
        height: u32,
    ) -> Result<Self, CalibrationError> {
        let calib = calib.for_size(width, height)?;
        let rect = calib.rectification(width, height);
        let (w, h) = (width as usize, height as usize);
        Ok(Self {
            left: RemapTable::build(&calib.k1, &calib.d1, &rect.r1, &rect.p1, w, h),
            right: RemapTable::build(&calib.k2, &calib.d2, &rect.r2, &rect.p2, w, h),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures")
            .join(name)
    }

    #[test]
    fn identity_calibration_gives_an_identity_remap() {
        let calib = StereoCalibration::load(&fixture("identity.yml")).unwrap();
        assert_eq!(calib.image_size, Some((64, 48)));
        assert!(calib.rectification.is_none());
        let rect = StereoRectifier::new(&calib, 64, 48).unwrap();
        assert!(rect.left.is_identity());
        assert!(rect.right.is_identity());
        let src: Vec<u8> = (0..64 * 48).map(|i| (i * 7 % 251) as u8).collect();
        let mut dst = vec![0u8; 64 * 48];
        rect.left.apply(&src, &mut dst).unwrap();
        assert_eq!(dst, src);
        // P2 carries the baseline: Tx * f = -60 * 50.
        let r = calib.rectification(64, 48);
        assert!((r.p2[3] + 3000.0).abs() < 1e-9, "{:?}", r.p2);
    }

    #[test]
    fn identity_calibration_scales_to_a_smaller_capture() {
        let calib = StereoCalibration::load(&fixture("identity.yml")).unwrap();
        let half = calib.for_size(32, 24).unwrap();
        assert_eq!(half.k1[0], 25.0);
        assert_eq!(half.k1[2], 15.75);
        let err = calib.for_size(40, 24).unwrap_err().to_string();
        assert!(
            err.contains("identity.yml") && err.contains("64x48"),
            "{err}"
        );
    }

    #[test]
    fn explicit_shift_gives_the_shifted_map() {
        let calib = StereoCalibration::load(&fixture("shifted.yml")).unwrap();
        assert!(calib.rectification.is_some());
        let rect = StereoRectifier::new(&calib, 64, 48).unwrap();
        assert!(rect.left.is_identity());
        assert_eq!(rect.right.source_of(10, 7), Some((7.0, 7.0)));
        assert_eq!(rect.right.source_of(2, 7), None);
        let src: Vec<u8> = (0..64 * 48).map(|i| (i % 64) as u8 * 3).collect();
        let mut dst = vec![0u8; 64 * 48];
        rect.right.apply(&src, &mut dst).unwrap();
        for u in 0..64 {
            let want = if u < 3 { 0 } else { (u as u8 - 3) * 3 };
            assert_eq!(dst[5 * 64 + u], want, "column {u}");
        }
    }

    #[test]
    fn computed_rectification_splits_a_vertical_offset() {
        let calib = StereoCalibration::load(&fixture("vertical.yml")).unwrap();
        let rect = StereoRectifier::new(&calib, 64, 48).unwrap();
        assert_eq!(rect.left.source_of(20, 20), Some((20.0, 18.0)));
        assert_eq!(rect.right.source_of(20, 20), Some((20.0, 22.0)));
    }

    #[test]
    fn bilinear_interpolation_of_half_pixels() {
        let table = RemapTable {
            width: 2,
            height: 1,
            entries: vec![
                MapEntry {
                    x: 0,
                    y: 0,
                    fx: 16,
                    fy: 0,
                },
                MapEntry {
                    x: 1,
                    y: 0,
                    fx: 0,
                    fy: 0,
                },
            ],
        };
        let mut dst = [0u8; 2];
        table.apply(&[10, 21], &mut dst).unwrap();
        assert_eq!(dst, [16, 21]); // (10 + 21) / 2 = 15.5, rounded up
        assert!(table.apply(&[1, 2, 3], &mut dst).is_err());
    }

    #[test]
    fn rodrigues_round_trips() {
        let v = [0.1, -0.2, 0.05];
        let back = rodrigues_to_vector(&rodrigues_to_matrix(v));
        for i in 0..3 {
            assert!((back[i] - v[i]).abs() < 1e-12, "{back:?}");
        }
    }

    #[test]
    fn distortion_inverts() {
        let d = [-0.3, 0.1, 0.001, -0.002, 0.0, 0.0, 0.0, 0.0];
        let (xd, yd) = distort(&d, 0.3, -0.2);
        let (x, y) = undistort(&d, xd, yd);
        assert!((x - 0.3).abs() < 1e-6 && (y + 0.2).abs() < 1e-6, "{x} {y}");
    }

    fn parse_err(text: &str) -> String {
        StereoCalibration::parse(text, Path::new("/cal/bad.yml"))
            .unwrap_err()
            .to_string()
    }

    fn identity_text() -> String {
        std::fs::read_to_string(fixture("identity.yml")).unwrap()
    }

    #[test]
    fn malformed_files_name_the_file_and_key() {
        let good = identity_text();
        let err = parse_err(&good.replace("K2:", "Kx:"));
        assert_eq!(err, "calibration file /cal/bad.yml has no `K2` or `M2`");
        let err = parse_err(&good.replace("[ -60., 0., 0. ]", "[ -60., 0. ]"));
        assert!(
            err.contains("/cal/bad.yml: `T` has 2 data values for rows = 3 x cols = 1"),
            "{err}"
        );
        let err = parse_err(&good.replace("[ -60., 0., 0. ]", "[ -60., zero, 0. ]"));
        assert!(
            err.contains("`T` has data value `zero`, not a number"),
            "{err}"
        );
        let err = parse_err(&good.replacen("   dt: d\n", "", 1));
        assert!(
            err.contains("`K1` is an opencv-matrix without `dt`"),
            "{err}"
        );
        let err = parse_err(&good.replace("[ 0., 0., 0., 0., 0. ]", "[ 0., 0., 0. ]"));
        assert!(
            err.contains("`D1`") && err.contains("rows = 1 x cols = 5"),
            "{err}"
        );
        let err = parse_err(&good.replace("[ -60., 0., 0. ]", "[ -60., 0., 0. "));
        assert!(err.contains("line") && err.contains("not closed"), "{err}");
        let err = parse_err(&format!(
            "{good}R1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]\n"
        ));
        assert!(
            err.contains("`R2` is missing (R1, R2, P1 and P2 go together)"),
            "{err}"
        );
        let err = parse_err(&good.replace(
            "[ 50., 0., 31.5, 0., 50., 23.5, 0., 0., 1. ]",
            "[ 0., 0., 31.5, 0., 50., 23.5, 0., 0., 1. ]",
        ));
        assert!(err.contains("`K1` is not a camera matrix"), "{err}");
        let err = parse_err("just text\n");
        assert!(
            err.contains("line 1") && err.contains("key: value"),
            "{err}"
        );
        let err = StereoCalibration::load(Path::new("/nonexistent/cal.yml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("cannot read calibration file /nonexistent/cal.yml"),
            "{err}"
        );
    }
}
