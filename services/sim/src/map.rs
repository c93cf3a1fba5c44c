//! 2-D text maps of walls and floor, the robot's start pose, and exact grid ray casting.
//!
//! # File format
//!
//! ```text
//! ; comment lines start with ';'
//! @name straight hallway      (optional, before the grid)
//! @cell_m 0.35                (optional cell edge in metres, default 0.5)
//! @wall_contrast 1            (optional, 0..1: 1 the full wall texture, 0 plain paint)
//! #######
//! #..>..#
//! #######
//! ```
//!
//! Each grid line is a row of cells, the first grid line is the northernmost row. `#` is a wall,
//! `.` is floor, a space is "no cell" (treated as wall, like everything outside the grid), and
//! exactly one start marker stands on a floor cell: `>` (heading 0 deg, east), `^` (90 deg,
//! north), `<` (180 deg, west), `v` (270 deg, south). Instead of a marker the start may be given
//! as a directive `@start x_m y_m heading_deg` for a pose that is not a cell centre (it must then
//! lie on floor). Rows may have different lengths; missing cells are walls, and an empty line
//! inside the grid is a row of wall. Blank lines before and after the grid are ignored.
//!
//! # World frame
//!
//! x east, y north, metres, origin at the bottom-left (south-west) corner of the grid, so the
//! last grid line covers `y` in `[0, cell_m)`. Headings are counter-clockwise from +x.

use std::f64::consts::PI;
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// Default cell edge length in metres when the map has no `@cell_m` directive.
pub const DEFAULT_CELL_M: f64 = 0.5;

/// Wall contrast when the map has no `@wall_contrast` directive: the full texture.
pub const DEFAULT_WALL_CONTRAST: f64 = 1.0;

/// The value of `@wall_contrast`, or why it is bad.
fn parse_wall_contrast(value: &str) -> Result<f64, &'static str> {
    let v: f64 = value
        .parse()
        .map_err(|_| "not a number (expected 0 to 1, e.g. 0.5)")?;
    if !(0.0..=1.0).contains(&v) {
        return Err("contrast must be between 0 (plain paint) and 1 (the full texture)");
    }
    Ok(v)
}

/// A 2-D vector or point in the world frame (metres when it is a point).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec2 {
    /// East component.
    pub x: f64,
    /// North component.
    pub y: f64,
}

impl Vec2 {
    /// Builds a vector from its components.
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// Unit vector pointing along `heading_rad` (CCW from +x).
    pub fn from_heading(heading_rad: f64) -> Self {
        Self::new(heading_rad.cos(), heading_rad.sin())
    }

    /// Euclidean length.
    pub fn length(self) -> f64 {
        self.x.hypot(self.y)
    }

    /// Dot product.
    pub fn dot(self, other: Vec2) -> f64 {
        self.x * other.x + self.y * other.y
    }
}

impl std::ops::Add for Vec2 {
    type Output = Vec2;
    fn add(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
}

impl std::ops::Sub for Vec2 {
    type Output = Vec2;
    fn sub(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
}

impl std::ops::Mul<f64> for Vec2 {
    type Output = Vec2;
    fn mul(self, k: f64) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }
}

/// A robot (or camera rig) pose in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// East position in metres.
    pub x_m: f64,
    /// North position in metres.
    pub y_m: f64,
    /// Heading in radians, counter-clockwise from +x (east).
    pub heading_rad: f64,
}

impl Pose {
    /// Builds a pose from metres and radians.
    pub const fn new(x_m: f64, y_m: f64, heading_rad: f64) -> Self {
        Self {
            x_m,
            y_m,
            heading_rad,
        }
    }

    /// Builds a pose from metres and a heading in degrees.
    pub fn from_deg(x_m: f64, y_m: f64, heading_deg: f64) -> Self {
        Self::new(x_m, y_m, heading_deg.to_radians())
    }

    /// Heading in degrees.
    pub fn heading_deg(&self) -> f64 {
        self.heading_rad.to_degrees()
    }

    /// Position as a vector.
    pub fn position(&self) -> Vec2 {
        Vec2::new(self.x_m, self.y_m)
    }

    /// Unit vector of the heading ("forward").
    pub fn forward(&self) -> Vec2 {
        Vec2::from_heading(self.heading_rad)
    }

    /// Unit vector 90 degrees to the left of the heading.
    pub fn left(&self) -> Vec2 {
        Vec2::from_heading(self.heading_rad + PI / 2.0)
    }

    /// This pose moved by `forward_m` along the heading and `left_m` to its left.
    pub fn offset(&self, forward_m: f64, left_m: f64) -> Pose {
        let p = self.position() + self.forward() * forward_m + self.left() * left_m;
        Pose::new(p.x, p.y, self.heading_rad)
    }
}

/// Error of [`Pose::from_str`] (text `x_m,y_m,heading_deg`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("bad pose {text:?}: {reason} (expected \"x_m,y_m,heading_deg\", e.g. \"1.5,2,90\")")]
pub struct PoseParseError {
    /// The text that failed to parse.
    pub text: String,
    /// What was wrong with it.
    pub reason: String,
}

impl FromStr for Pose {
    type Err = PoseParseError;

    /// Parses `x_m,y_m,heading_deg` (the CLI's `--pose` format).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |reason: String| PoseParseError {
            text: s.to_string(),
            reason,
        };
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        if parts.len() != 3 {
            return Err(err(format!("{} comma-separated values", parts.len())));
        }
        let mut v = [0.0f64; 3];
        for (slot, (part, what)) in
            v.iter_mut()
                .zip(parts.iter().zip(["x_m", "y_m", "heading_deg"]))
        {
            *slot = part
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err(format!("{what} {part:?} is not a finite number")))?;
        }
        Ok(Pose::from_deg(v[0], v[1], v[2]))
    }
}

/// Which face of a wall cell a ray hit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Face {
    /// The face at the cell's west edge (normal points west, -x).
    West,
    /// The face at the cell's east edge (normal points east, +x).
    East,
    /// The face at the cell's south edge (normal points south, -y).
    South,
    /// The face at the cell's north edge (normal points north, +y).
    North,
}

impl Face {
    /// Outward unit normal of the face.
    pub fn normal(self) -> Vec2 {
        match self {
            Face::West => Vec2::new(-1.0, 0.0),
            Face::East => Vec2::new(1.0, 0.0),
            Face::South => Vec2::new(0.0, -1.0),
            Face::North => Vec2::new(0.0, 1.0),
        }
    }

    /// Small index 0..4 (West, East, South, North), handy for seeding textures.
    pub fn index(self) -> u32 {
        match self {
            Face::West => 0,
            Face::East => 1,
            Face::South => 2,
            Face::North => 3,
        }
    }
}

/// Result of [`GridMap::cast_ray`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// Euclidean distance from the ray origin to the hit point, metres.
    pub distance_m: f64,
    /// The hit point on the wall face, world metres.
    pub point: Vec2,
    /// The face that was hit.
    pub face: Face,
    /// Outward unit normal of the hit face (same as `face.normal()`).
    pub normal: Vec2,
    /// Column (from the west, 0-based) of the wall cell hit; may be -1 or `width_cells` outside.
    pub cell_col: i64,
    /// Row from the south (0-based, 0 = last text line) of the wall cell hit; may be -1 or
    /// `height_cells` outside the grid.
    pub cell_row: i64,
    /// Coordinate along the face, metres from the face's west end (N/S faces) or south end
    /// (E/W faces), in `[0, cell_m]`.
    pub u_m: f64,
}

/// Errors of [`GridMap::parse`] and [`GridMap::load`]. Line and column numbers are 1-based.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// The map file could not be read.
    #[error("cannot read map file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A grid line holds a character that is not a cell.
    #[error(
        "{source_name}:{line}:{col}: unknown map character {ch:?} (expected '#', '.', ' ', '>', '^', '<' or 'v')"
    )]
    UnknownChar {
        /// File or source name.
        source_name: String,
        /// Line number.
        line: usize,
        /// Column number (in characters).
        col: usize,
        /// The offending character.
        ch: char,
    },
    /// The map has no start marker and no `@start` directive.
    #[error(
        "{source_name}: no start marker (put one of '>', '^', '<', 'v' on a floor cell, or an @start directive)"
    )]
    NoStart {
        /// File or source name.
        source_name: String,
    },
    /// The map has more than one start.
    #[error(
        "{source_name}:{line}:{col}: second start marker (the first is at line {first_line}, column {first_col})"
    )]
    MultipleStarts {
        /// File or source name.
        source_name: String,
        /// Line of the second start.
        line: usize,
        /// Column of the second start.
        col: usize,
        /// Line of the first start.
        first_line: usize,
        /// Column of the first start.
        first_col: usize,
    },
    /// The `@start` pose lies inside a wall or outside the grid.
    #[error(
        "{source_name}:{line}: start pose x={x_m} m, y={y_m} m lies on a wall or outside the grid"
    )]
    StartOnWall {
        /// File or source name.
        source_name: String,
        /// Line of the `@start` directive.
        line: usize,
        /// Start x.
        x_m: f64,
        /// Start y.
        y_m: f64,
    },
    /// The map has no grid lines (or only empty ones).
    #[error("{source_name}: empty map (no grid lines)")]
    Empty {
        /// File or source name.
        source_name: String,
    },
    /// A directive has a missing or invalid value.
    #[error("{source_name}:{line}:{col}: bad value {value:?} for @{directive}: {reason}")]
    BadDirective {
        /// File or source name.
        source_name: String,
        /// Line number.
        line: usize,
        /// Column where the value starts.
        col: usize,
        /// Directive name without '@'.
        directive: String,
        /// The value text.
        value: String,
        /// Why it is invalid.
        reason: String,
    },
    /// A directive that the format does not know.
    #[error(
        "{source_name}:{line}:1: unknown directive @{directive} (known: @cell_m, @name, @start, @wall_contrast)"
    )]
    UnknownDirective {
        /// File or source name.
        source_name: String,
        /// Line number.
        line: usize,
        /// Directive name without '@'.
        directive: String,
    },
    /// A directive after the first grid line.
    #[error("{source_name}:{line}:1: directive after the grid (directives must come first)")]
    DirectiveAfterGrid {
        /// File or source name.
        source_name: String,
        /// Line number.
        line: usize,
    },
}

/// A 2-D occupancy grid map with a start pose.
#[derive(Clone, PartialEq)]
pub struct GridMap {
    name: String,
    source_name: String,
    cell_m: f64,
    width: usize,
    height: usize,
    /// `walls[row * width + col]`, row 0 = south.
    walls: Vec<bool>,
    start: Pose,
    seed: u64,
    /// Contrast of the wall texture around its mean, 0..=1 (`@wall_contrast`).
    wall_contrast: f64,
}

impl fmt::Debug for GridMap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GridMap")
            .field("name", &self.name)
            .field("source_name", &self.source_name)
            .field("cell_m", &self.cell_m)
            .field("width_cells", &self.width)
            .field("height_cells", &self.height)
            .field("start", &self.start)
            .finish_non_exhaustive()
    }
}

fn fnv1a(seed: u64, bytes: &[u8]) -> u64 {
    let mut h = seed ^ 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

impl GridMap {
    /// Reads and parses a map file; errors name the file.
    pub fn load(path: impl AsRef<Path>) -> Result<GridMap, MapError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| MapError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        GridMap::parse(&text, &path.display().to_string())
    }

    /// Parses map text; `source_name` (a file name, usually) is used in error messages.
    pub fn parse(text: &str, source_name: &str) -> Result<GridMap, MapError> {
        let src = || source_name.to_string();
        let mut name = String::new();
        let mut cell_m = DEFAULT_CELL_M;
        let mut wall_contrast = DEFAULT_WALL_CONTRAST;
        // (line number, text) of grid lines, top first.
        let mut rows: Vec<(usize, &str)> = Vec::new();
        let mut directive_start: Option<(usize, f64, f64, f64)> = None;
        for (idx, raw) in text.lines().enumerate() {
            let line_no = idx + 1;
            let line = raw.trim_end();
            if line.starts_with(';') {
                continue;
            }
            if let Some(rest) = line.strip_prefix('@') {
                if !rows.is_empty() {
                    return Err(MapError::DirectiveAfterGrid {
                        source_name: src(),
                        line: line_no,
                    });
                }
                let key_len = rest.find(char::is_whitespace).unwrap_or(rest.len());
                let key = &rest[..key_len];
                let after_key = &rest[key_len..];
                let value = after_key.trim();
                // Column (1-based, chars) where the value starts.
                let value_col = 2
                    + key.chars().count()
                    + (after_key.chars().count() - after_key.trim_start().chars().count());
                let bad = |reason: &str| MapError::BadDirective {
                    source_name: src(),
                    line: line_no,
                    col: value_col,
                    directive: key.to_string(),
                    value: value.to_string(),
                    reason: reason.to_string(),
                };
                match key {
                    "cell_m" => {
                        let v: f64 = value
                            .parse()
                            .map_err(|_| bad("not a number (expected metres, e.g. 0.5)"))?;
                        if !(v.is_finite() && (0.01..=10.0).contains(&v)) {
                            return Err(bad("cell edge must be between 0.01 and 10 m"));
                        }
                        cell_m = v;
                    }
                    "wall_contrast" => {
                        wall_contrast = parse_wall_contrast(value).map_err(bad)?;
                    }
                    "name" => {
                        if value.is_empty() {
                            return Err(bad("empty name"));
                        }
                        name = value.to_string();
                    }
                    "start" => {
                        let nums: Vec<f64> = value
                            .split_whitespace()
                            .map(|t| t.parse::<f64>().ok().filter(|v| v.is_finite()))
                            .collect::<Option<Vec<f64>>>()
                            .ok_or_else(|| bad("expected three numbers: x_m y_m heading_deg"))?;
                        if nums.len() != 3 {
                            return Err(bad("expected three numbers: x_m y_m heading_deg"));
                        }
                        if directive_start.is_some() {
                            return Err(bad("second @start directive"));
                        }
                        directive_start = Some((line_no, nums[0], nums[1], nums[2]));
                    }
                    _ => {
                        return Err(MapError::UnknownDirective {
                            source_name: src(),
                            line: line_no,
                            directive: key.to_string(),
                        });
                    }
                }
                continue;
            }
            if rows.is_empty() && line.is_empty() {
                continue; // blank lines before the grid
            }
            rows.push((line_no, line));
        }
        while rows.last().is_some_and(|(_, l)| l.is_empty()) {
            rows.pop();
        }
        if rows.is_empty() {
            return Err(MapError::Empty { source_name: src() });
        }
        let height = rows.len();
        let width = rows
            .iter()
            .map(|(_, l)| l.chars().count())
            .max()
            .unwrap_or(0);
        if width == 0 {
            return Err(MapError::Empty { source_name: src() });
        }
        let mut walls = vec![true; width * height];
        let mut marker: Option<(usize, usize, usize, usize, f64)> = None; // line, col, gcol, grow, heading_deg
        for (text_row, (line_no, line)) in rows.iter().enumerate() {
            let grow = height - 1 - text_row;
            for (ci, ch) in line.chars().enumerate() {
                let heading_deg = match ch {
                    '#' | ' ' => continue,
                    '.' => None,
                    '>' => Some(0.0),
                    '^' => Some(90.0),
                    '<' => Some(180.0),
                    'v' => Some(270.0),
                    _ => {
                        return Err(MapError::UnknownChar {
                            source_name: src(),
                            line: *line_no,
                            col: ci + 1,
                            ch,
                        });
                    }
                };
                walls[grow * width + ci] = false;
                if let Some(h) = heading_deg {
                    if let Some((fl, fc, ..)) = marker {
                        return Err(MapError::MultipleStarts {
                            source_name: src(),
                            line: *line_no,
                            col: ci + 1,
                            first_line: fl,
                            first_col: fc,
                        });
                    }
                    marker = Some((*line_no, ci + 1, ci, grow, h));
                }
            }
        }
        let mut map = GridMap {
            name,
            source_name: source_name.to_string(),
            cell_m,
            width,
            height,
            walls,
            start: Pose::default(),
            seed: 0,
            wall_contrast,
        };
        map.start = match (marker, directive_start) {
            (Some((ml, mc, ..)), Some((dl, ..))) => {
                return Err(MapError::MultipleStarts {
                    source_name: src(),
                    line: ml,
                    col: mc,
                    first_line: dl,
                    first_col: 1,
                });
            }
            (None, None) => {
                return Err(MapError::NoStart { source_name: src() });
            }
            (Some((_, _, gcol, grow, h)), None) => Pose::from_deg(
                (gcol as f64 + 0.5) * cell_m,
                (grow as f64 + 0.5) * cell_m,
                h,
            ),
            (None, Some((line, x_m, y_m, h))) => {
                if map.is_wall_at(x_m, y_m) {
                    return Err(MapError::StartOnWall {
                        source_name: src(),
                        line,
                        x_m,
                        y_m,
                    });
                }
                Pose::from_deg(x_m, y_m, h)
            }
        };
        let mut seed = fnv1a(0, map.name.as_bytes());
        seed = fnv1a(seed, &cell_m.to_le_bytes());
        seed = fnv1a(seed, &(width as u64).to_le_bytes());
        let packed: Vec<u8> = map.walls.iter().map(|&w| u8::from(w)).collect();
        map.seed = fnv1a(seed, &packed);
        Ok(map)
    }

    /// The map's `@name` (empty if none was given).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The source name given to [`GridMap::parse`] (the file path for [`GridMap::load`]).
    pub fn source_name(&self) -> &str {
        &self.source_name
    }

    /// Cell edge length in metres.
    pub fn cell_m(&self) -> f64 {
        self.cell_m
    }

    /// Number of cell columns (west to east).
    pub fn width_cells(&self) -> usize {
        self.width
    }

    /// Number of cell rows (south to north).
    pub fn height_cells(&self) -> usize {
        self.height
    }

    /// Width of the grid in metres.
    pub fn width_m(&self) -> f64 {
        self.width as f64 * self.cell_m
    }

    /// Height of the grid in metres.
    pub fn height_m(&self) -> f64 {
        self.height as f64 * self.cell_m
    }

    /// The start pose (cell centre of the marker, or the `@start` pose).
    pub fn start_pose(&self) -> Pose {
        self.start
    }

    /// Contrast of the wall texture around its mean (`@wall_contrast`, default 1): 1 is the
    /// full procedural texture, 0 plain paint (one flat grey per wall run), in between the
    /// texture's deviations from its mean scaled by it.
    pub fn wall_contrast(&self) -> f64 {
        self.wall_contrast
    }

    /// Sets the wall contrast (clamped to 0..=1; a NaN leaves it as it is). Set it before
    /// building a renderer or world from the map: they keep a copy.
    pub fn set_wall_contrast(&mut self, contrast: f64) {
        if !contrast.is_nan() {
            self.wall_contrast = contrast.clamp(0.0, 1.0);
        }
    }

    /// A deterministic seed derived from the map's name, cell size and walls (for textures).
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Whether cell (`col` from the west, `row` from the south) is a wall; outside the grid is wall.
    pub fn is_wall_cell(&self, col: i64, row: i64) -> bool {
        if col < 0 || row < 0 || col >= self.width as i64 || row >= self.height as i64 {
            return true;
        }
        self.walls[row as usize * self.width + col as usize]
    }

    /// Cell indices (col, row) containing the world point.
    pub fn cell_of(&self, x_m: f64, y_m: f64) -> (i64, i64) {
        (
            (x_m / self.cell_m).floor() as i64,
            (y_m / self.cell_m).floor() as i64,
        )
    }

    /// Whether the world point lies in a wall cell or outside the grid (non-finite points count as wall).
    pub fn is_wall_at(&self, x_m: f64, y_m: f64) -> bool {
        if !(x_m.is_finite() && y_m.is_finite()) {
            return true;
        }
        let (c, r) = self.cell_of(x_m, y_m);
        self.is_wall_cell(c, r)
    }

    /// Casts a ray from `origin` along `dir` (any non-zero length) and returns the first wall face
    /// hit, using an exact grid traversal (Amanatides & Woo). Returns `None` when `origin` is in a
    /// wall or outside the grid, or `dir` is zero or not finite.
    pub fn cast_ray(&self, origin: Vec2, dir: Vec2) -> Option<RayHit> {
        let len = dir.length();
        if !(len.is_finite() && len > 0.0) || self.is_wall_at(origin.x, origin.y) {
            return None;
        }
        let d = dir * (1.0 / len);
        let cs = self.cell_m;
        let (mut col, mut row) = self.cell_of(origin.x, origin.y);
        let step_c: i64 = if d.x > 0.0 { 1 } else { -1 };
        let step_r: i64 = if d.y > 0.0 { 1 } else { -1 };
        let inv_x = if d.x != 0.0 {
            1.0 / d.x.abs()
        } else {
            f64::INFINITY
        };
        let inv_y = if d.y != 0.0 {
            1.0 / d.y.abs()
        } else {
            f64::INFINITY
        };
        // Distance to the next x / y cell boundary.
        let next_x_boundary = if d.x > 0.0 {
            (col + 1) as f64 * cs
        } else {
            col as f64 * cs
        };
        let next_y_boundary = if d.y > 0.0 {
            (row + 1) as f64 * cs
        } else {
            row as f64 * cs
        };
        let mut t_max_x = if d.x != 0.0 {
            (next_x_boundary - origin.x).abs() * inv_x
        } else {
            f64::INFINITY
        };
        let mut t_max_y = if d.y != 0.0 {
            (next_y_boundary - origin.y).abs() * inv_y
        } else {
            f64::INFINITY
        };
        let t_delta_x = cs * inv_x;
        let t_delta_y = cs * inv_y;
        // The grid is surrounded by wall, so at most width + height + 2 steps are needed.
        let max_steps = self.width + self.height + 4;
        for _ in 0..max_steps {
            let (t, face, x_step) = if t_max_x < t_max_y {
                let t = t_max_x;
                col += step_c;
                t_max_x += t_delta_x;
                (t, if step_c > 0 { Face::West } else { Face::East }, true)
            } else {
                let t = t_max_y;
                row += step_r;
                t_max_y += t_delta_y;
                (t, if step_r > 0 { Face::South } else { Face::North }, false)
            };
            if self.is_wall_cell(col, row) {
                // Snap the coordinate on the boundary exactly; compute the other from t.
                let point = if x_step {
                    let x = if step_c > 0 {
                        col as f64 * cs
                    } else {
                        (col + 1) as f64 * cs
                    };
                    Vec2::new(x, origin.y + d.y * t)
                } else {
                    let y = if step_r > 0 {
                        row as f64 * cs
                    } else {
                        (row + 1) as f64 * cs
                    };
                    Vec2::new(origin.x + d.x * t, y)
                };
                let u_m = if x_step {
                    (point.y - row as f64 * cs).clamp(0.0, cs)
                } else {
                    (point.x - col as f64 * cs).clamp(0.0, cs)
                };
                return Some(RayHit {
                    distance_m: t,
                    point,
                    face,
                    normal: face.normal(),
                    cell_col: col,
                    cell_row: row,
                    u_m,
                });
            }
        }
        None
    }

    /// Whether an oriented rectangle (centre `pose`, `length_m` along the heading, `width_m`
    /// across) overlaps any wall cell or leaves the grid. Exact (separating-axis test).
    pub fn rect_hits_wall(&self, pose: &Pose, length_m: f64, width_m: f64) -> bool {
        let f = pose.forward();
        let l = pose.left();
        let hl = length_m / 2.0;
        let hw = width_m / 2.0;
        let c = pose.position();
        let corners = [
            c + f * hl + l * hw,
            c + f * hl - l * hw,
            c - f * hl + l * hw,
            c - f * hl - l * hw,
        ];
        let (mut min_x, mut max_x, mut min_y, mut max_y) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for p in &corners {
            min_x = min_x.min(p.x);
            max_x = max_x.max(p.x);
            min_y = min_y.min(p.y);
            max_y = max_y.max(p.y);
        }
        if !(min_x.is_finite() && max_x.is_finite() && min_y.is_finite() && max_y.is_finite()) {
            return true;
        }
        let cs = self.cell_m;
        let c0 = (min_x / cs).floor() as i64;
        let c1 = (max_x / cs).floor() as i64;
        let r0 = (min_y / cs).floor() as i64;
        let r1 = (max_y / cs).floor() as i64;
        // Half-extent of the rectangle projected on a unit axis `a`.
        let rect_radius = |a: Vec2| hl * f.dot(a).abs() + hw * l.dot(a).abs();
        for row in r0..=r1 {
            for col in c0..=c1 {
                if !self.is_wall_cell(col, row) {
                    continue;
                }
                let cell_min = Vec2::new(col as f64 * cs, row as f64 * cs);
                let cell_c = cell_min + Vec2::new(cs / 2.0, cs / 2.0);
                let delta = cell_c - c;
                // Axes: x, y (cell), f, l (rectangle). Touching (equality) is not overlap.
                let mut separated = false;
                for a in [Vec2::new(1.0, 0.0), Vec2::new(0.0, 1.0), f, l] {
                    let cell_r = cs / 2.0 * (a.x.abs() + a.y.abs());
                    if delta.dot(a).abs() >= cell_r + rect_radius(a) {
                        separated = true;
                        break;
                    }
                }
                if !separated {
                    return true;
                }
            }
        }
        false
    }
}

#[cfg(test)]
mod tests;
