//! World-anchored procedural textures for walls, floor and ceiling.
//!
//! Every texture is a pure function of world coordinates (and of the map's seed), so both eyes of
//! the stereo rig see exactly the same surface pattern. Patterns are band-limited against the
//! pixel footprint: each layer of scale `s` fades out as the footprint `fp` (metres covered by one
//! pixel on the surface) approaches `s`, and rectangular features (grout, frames, posters) are
//! drawn with analytic box-filtered coverage. This keeps aliasing low without supersampling.
//!
//! Smallest feature sizes: paint speckle 1.2 cm, floor grain 1.2 cm, grout 1.2 cm, poster blobs
//! 2.5-6 cm.

use std::sync::OnceLock;

use crate::map::{Face, GridMap};

/// Wall height in metres (walls stand on the floor and meet the flat ceiling).
pub const WALL_HEIGHT_M: f64 = 2.4;

/// Height of the dark baseboard at the foot of every wall, metres.
pub const BASEBOARD_M: f32 = 0.10;

/// Floor tile edge, metres.
pub const FLOOR_TILE_M: f32 = 0.30;

/// Ceiling panel edge, metres.
pub const CEILING_PANEL_M: f32 = 0.60;

const NOISE_BITS: u32 = 8;
const NOISE_SIZE: usize = 1 << NOISE_BITS;
const NOISE_MASK: i32 = (NOISE_SIZE as i32) - 1;
/// Offset added before truncating to integers so that `as i32` acts as `floor` (coordinates of a
/// map are far smaller than this in noise cells).
const POS_OFFSET: f32 = 1024.0;

/// 32-bit integer hash (lowbias32, public domain).
#[inline(always)]
pub(crate) fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Hash of two integers and a seed.
#[inline(always)]
pub(crate) fn hash3(a: i32, b: i32, seed: u32) -> u32 {
    hash32((a as u32) ^ hash32((b as u32) ^ hash32(seed)))
}

/// Uniform value in `[0, 1)` from a hash.
#[inline(always)]
pub(crate) fn unit(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A periodic table of random values in `[-1, 1]` for bilinear value noise.
pub(crate) struct NoiseTable {
    v: Vec<f32>,
}

impl NoiseTable {
    fn new() -> Self {
        let v = (0..NOISE_SIZE * NOISE_SIZE)
            .map(|i| unit(hash32(i as u32 ^ 0x9e37_79b9)) * 2.0 - 1.0)
            .collect();
        Self { v }
    }

    /// The process-wide table (deterministic contents).
    pub(crate) fn get() -> &'static NoiseTable {
        static TABLE: OnceLock<NoiseTable> = OnceLock::new();
        TABLE.get_or_init(NoiseTable::new)
    }

    /// Bilinear value noise at (x, y) in noise cells, shifted by integer cell offsets (ox, oy).
    /// Returns a value in `[-1, 1]`.
    #[inline(always)]
    pub(crate) fn at(&self, x: f32, y: f32, ox: i32, oy: i32) -> f32 {
        let xp = x + POS_OFFSET;
        let yp = y + POS_OFFSET;
        let xi = xp as i32;
        let yi = yp as i32;
        let fx = xp - xi as f32;
        let fy = yp - yi as f32;
        let x0 = (xi + ox) & NOISE_MASK;
        let y0 = (yi + oy) & NOISE_MASK;
        let x1 = (x0 + 1) & NOISE_MASK;
        let y1 = (y0 + 1) & NOISE_MASK;
        let r0 = (y0 << NOISE_BITS) as usize;
        let r1 = (y1 << NOISE_BITS) as usize;
        let v = &self.v[..NOISE_SIZE * NOISE_SIZE];
        let a = v[(r0 | x0 as usize) & (NOISE_SIZE * NOISE_SIZE - 1)];
        let b = v[(r0 | x1 as usize) & (NOISE_SIZE * NOISE_SIZE - 1)];
        let c = v[(r1 | x0 as usize) & (NOISE_SIZE * NOISE_SIZE - 1)];
        let d = v[(r1 | x1 as usize) & (NOISE_SIZE * NOISE_SIZE - 1)];
        let top = a + (b - a) * fx;
        let bot = c + (d - c) * fx;
        top + (bot - top) * fy
    }
}

/// Weight of a texture layer of feature scale `scale_m` seen with pixel footprint `fp_m`:
/// 1 when the feature spans 2.5 pixels or more, 0 at one pixel or less.
#[inline(always)]
pub(crate) fn band_weight(scale_m: f32, fp_m: f32) -> f32 {
    ((scale_m / fp_m.max(1e-6) - 1.0) * (1.0 / 1.5)).clamp(0.0, 1.0)
}

/// Fraction of the box `[x - fp/2, x + fp/2]` covered by the interval `[a, b]`.
#[inline(always)]
pub(crate) fn interval_cov(x: f32, a: f32, b: f32, fp_m: f32) -> f32 {
    let h = 0.5 * fp_m.max(1e-6);
    let lo = (x - h).max(a);
    let hi = (x + h).min(b);
    ((hi - lo) / (2.0 * h)).clamp(0.0, 1.0)
}

#[inline(always)]
pub(crate) fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// What kind of decoration hangs on a wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum DecorKind {
    /// A door with a dark frame.
    Door,
    /// A poster with high-contrast random content of blob scale `blob_m`.
    Poster {
        /// Blob scale of the poster content, metres.
        blob_m: f32,
    },
}

/// A wall decoration: an axis-aligned rectangle on a wall run, in world coordinates along the
/// wall (`s`, metres: x for north/south faces, y for east/west faces) and height `z`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Decor {
    pub(crate) s0: f32,
    pub(crate) s1: f32,
    pub(crate) z0: f32,
    pub(crate) z1: f32,
    pub(crate) kind: DecorKind,
    pub(crate) seed: u32,
}

/// Door geometry.
pub(crate) const DOOR_WIDTH_M: f32 = 1.02;
pub(crate) const DOOR_HEIGHT_M: f32 = 2.10;
pub(crate) const DOOR_FRAME_M: f32 = 0.06;

/// One maximal straight run of visible wall faces, with its decorations.
#[derive(Debug, Clone)]
pub(crate) struct WallRun {
    /// Per-line seed (decorrelates texture of different walls).
    pub(crate) seed: u32,
    pub(crate) decor: Vec<Decor>,
    /// This run's flat paint at zero wall contrast, grey levels from [`WALL_PAINT_MEAN`]:
    /// walls facing east or west a little lighter, walls facing north or south a little
    /// darker (as a plain hallway's walls are lit differently), each run by its own amount.
    pub(crate) paint_offset: f32,
}

/// Decorations of a whole map, looked up by the wall cell and face a ray hit.
#[derive(Debug, Clone)]
pub(crate) struct SceneDecor {
    width: i64,
    height: i64,
    /// `(row + 1) * (width + 2) + (col + 1)` times 4 plus face index -> run index (u32::MAX = none).
    face_run: Vec<u32>,
    pub(crate) runs: Vec<WallRun>,
    pub(crate) seed: u32,
}

/// A small deterministic generator for decoration layout (SplitMix64).
struct SplitMix(u64);

impl SplitMix {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * ((self.next_u64() >> 40) as f32 / 16_777_216.0)
    }
}

impl SceneDecor {
    /// Finds the wall runs of `map` and lays out doors and posters on them.
    pub(crate) fn new(map: &GridMap) -> Self {
        let width = map.width_cells() as i64;
        let height = map.height_cells() as i64;
        let seed = (map.seed() ^ (map.seed() >> 32)) as u32;
        let cs = map.cell_m() as f32;
        let mut face_run = vec![u32::MAX; ((width + 2) * (height + 2) * 4) as usize];
        let mut runs = Vec::new();
        let idx = |col: i64, row: i64, face: Face| -> usize {
            (((row + 1) * (width + 2) + (col + 1)) * 4 + face.index() as i64) as usize
        };
        // A face of wall cell (col,row) is visible when the neighbour on that side is floor.
        let visible = |col: i64, row: i64, face: Face| -> bool {
            if !map.is_wall_cell(col, row) {
                return false;
            }
            let (dc, dr) = match face {
                Face::West => (-1, 0),
                Face::East => (1, 0),
                Face::South => (0, -1),
                Face::North => (0, 1),
            };
            !map.is_wall_cell(col + dc, row + dr)
        };
        for face in [Face::West, Face::East, Face::South, Face::North] {
            let along_x = matches!(face, Face::South | Face::North);
            let (lines, len) = if along_x {
                (height + 2, width + 2)
            } else {
                (width + 2, height + 2)
            };
            for line in -1..lines - 1 {
                let mut k = -1;
                while k < len - 1 {
                    let cell = |k: i64| if along_x { (k, line) } else { (line, k) };
                    let (c, r) = cell(k);
                    if !visible(c, r, face) {
                        k += 1;
                        continue;
                    }
                    let start = k;
                    while k < len - 1 && {
                        let (c, r) = cell(k);
                        visible(c, r, face)
                    } {
                        k += 1;
                    }
                    let end = k; // exclusive
                    let run_index = runs.len() as u32;
                    for j in start..end {
                        let (c, r) = cell(j);
                        face_run[idx(c, r, face)] = run_index;
                    }
                    let run_seed = hash32(
                        seed ^ hash32(
                            (face.index() << 24) ^ ((line + 1) as u32) << 12 ^ (start + 1) as u32,
                        ),
                    );
                    let s_start = start as f32 * cs;
                    let s_end = end as f32 * cs;
                    let shade =
                        PLAIN_PAINT_MIN + PLAIN_PAINT_SPREAD * unit(hash32(run_seed ^ 0x5a17_c0de));
                    runs.push(WallRun {
                        seed: run_seed,
                        decor: layout_decor(run_seed, s_start, s_end),
                        paint_offset: if along_x { -shade } else { shade },
                    });
                }
            }
        }
        SceneDecor {
            width,
            height,
            face_run,
            runs,
            seed,
        }
    }

    /// The wall run of a hit face, if the face is a visible one.
    #[inline]
    pub(crate) fn run_of(&self, col: i64, row: i64, face: Face) -> Option<&WallRun> {
        if col < -1 || row < -1 || col > self.width || row > self.height {
            return None;
        }
        let i = (((row + 1) * (self.width + 2) + (col + 1)) * 4 + face.index() as i64) as usize;
        let r = *self.face_run.get(i)?;
        self.runs.get(r as usize)
    }
}

/// Lays out doors and posters along a run `[s_start, s_end]`.
fn layout_decor(seed: u32, s_start: f32, s_end: f32) -> Vec<Decor> {
    let mut rng = SplitMix(u64::from(seed) << 1 | 1);
    let mut out = Vec::new();
    let mut cursor = s_start + rng.range(0.15, 0.8);
    let mut last_door_end = f32::NEG_INFINITY;
    while cursor < s_end {
        let r = rng.range(0.0, 1.0);
        let item_seed = (rng.next_u64() >> 32) as u32;
        if r < 0.4 && cursor - last_door_end > 1.5 && cursor + DOOR_WIDTH_M <= s_end - 0.15 {
            out.push(Decor {
                s0: cursor,
                s1: cursor + DOOR_WIDTH_M,
                z0: 0.0,
                z1: DOOR_HEIGHT_M,
                kind: DecorKind::Door,
                seed: item_seed,
            });
            cursor += DOOR_WIDTH_M;
            last_door_end = cursor;
            cursor += rng.range(0.3, 1.0);
        } else if r < 0.85 {
            let w = rng.range(0.3, 0.9);
            if cursor + w > s_end - 0.1 {
                // Try a narrower poster once before giving up on this run.
                let w2 = s_end - 0.1 - cursor;
                if w2 < 0.22 {
                    break;
                }
                out.push(poster(&mut rng, cursor, w2, item_seed));
                break;
            }
            out.push(poster(&mut rng, cursor, w, item_seed));
            cursor += w + rng.range(0.25, 1.0);
        } else {
            cursor += rng.range(0.3, 1.0);
        }
    }
    out
}

fn poster(rng: &mut SplitMix, s0: f32, w: f32, seed: u32) -> Decor {
    let h = rng.range(0.3, 0.85);
    let z0 = rng.range(0.85, 1.35);
    Decor {
        s0,
        s1: s0 + w,
        z0,
        z1: z0 + h,
        kind: DecorKind::Poster {
            blob_m: rng.range(0.025, 0.06),
        },
        seed,
    }
}

/// Periodic bilinear value noise from hashed lattice values: lattice period `px` x `py` cells.
fn periodic_vnoise(x: f32, y: f32, px: i32, py: i32, seed: u32) -> f32 {
    let xf = x.floor();
    let yf = y.floor();
    let (fx, fy) = (x - xf, y - yf);
    let (xi, yi) = (xf as i32, yf as i32);
    let val = |i: i32, j: i32| unit(hash3(i.rem_euclid(px), j.rem_euclid(py), seed)) * 2.0 - 1.0;
    let top = lerp(val(xi, yi), val(xi + 1, yi), fx);
    let bot = lerp(val(xi, yi + 1), val(xi + 1, yi + 1), fx);
    lerp(top, bot, fy)
}

/// Splits a texture coordinate into an integer texel index and a weight in `[0, 1]` for
/// bilinear interpolation, without float-to-int conversion: adding 1.5 * 2^23 rounds to an
/// integer in the mantissa. The index is `round(x - 0.5)`, i.e. `floor(x)` except that an exact
/// integer may give `(x - 1, 1.0)`, which interpolates to the same value. Valid for
/// `|x| < 2^21` (texture coordinates stay far below that).
#[inline(always)]
fn split(x: f32) -> (i32, f32) {
    const MAGIC: f32 = 12_582_912.0;
    let t = (x - 0.5) + MAGIC;
    let i = (t.to_bits() as i32).wrapping_sub(MAGIC.to_bits() as i32);
    (i, x - (t - MAGIC))
}

/// One level of a [`RipMap`]: a power-of-two periodic texture of grey values, stored row-major
/// (floor, ceiling) or column-major (walls, which are drawn column by column).
#[derive(Debug)]
struct Level {
    /// log2 of the memory stride between horizontally adjacent texels.
    x_stride_log: u32,
    /// log2 of the memory stride between vertically adjacent texels.
    y_stride_log: u32,
    wmask: i32,
    hmask: i32,
    data: Vec<f32>,
}

/// Two horizontally interpolated texel rows of one column lookup, reused between pixels.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RowCache {
    yi: i32,
    top: f32,
    bot: f32,
}

impl Default for RowCache {
    fn default() -> Self {
        RowCache {
            yi: i32::MIN,
            top: 0.0,
            bot: 0.0,
        }
    }
}

/// The last texel quad of a floor/ceiling row lookup, reused between pixels.
#[derive(Debug, Clone, Copy)]
pub(crate) struct QuadCache {
    xi: i32,
    yi: i32,
    q: [f32; 4],
}

impl Default for QuadCache {
    fn default() -> Self {
        QuadCache {
            xi: i32::MIN,
            yi: i32::MIN,
            q: [0.0; 4],
        }
    }
}

/// Per-column shading state: the row caches of the paint levels and the detail layer.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct ShadeState {
    c0: RowCache,
    c1: RowCache,
    cd: RowCache,
}

/// Horizontal part of a bilinear lookup (memory offsets of two texel columns and a weight).
#[derive(Debug, Clone, Copy, Default)]
struct XPart {
    c0: usize,
    c1: usize,
    fx: f32,
}

impl Level {
    #[inline(always)]
    fn xpart(&self, u: f32) -> XPart {
        let (xi, fx) = split(u);
        XPart {
            c0: ((xi & self.wmask) as usize) << self.x_stride_log,
            c1: (((xi + 1) & self.wmask) as usize) << self.x_stride_log,
            fx,
        }
    }

    /// Bilinear sample at level texel coordinates (texel centres at integers) that reuses the two horizontally interpolated texel rows kept
    /// in `cache` while consecutive lookups stay between the same texel rows (walking down a
    /// magnified wall column, many pixels share them).
    #[inline(always)]
    fn sample_x_cached(&self, xp: XPart, v: f32, cache: &mut RowCache) -> f32 {
        let (yi, fy) = split(v);
        if yi != cache.yi {
            let r0 = ((yi & self.hmask) as usize) << self.y_stride_log;
            let r1 = (((yi + 1) & self.hmask) as usize) << self.y_stride_log;
            let d = &self.data;
            cache.top = lerp(d[r0 + xp.c0], d[r0 + xp.c1], xp.fx);
            cache.bot = lerp(d[r1 + xp.c0], d[r1 + xp.c1], xp.fx);
            cache.yi = yi;
        }
        lerp(cache.top, cache.bot, fy)
    }

    /// Re-stores the texels column-major.
    fn into_column_major(self, w_log: u32, h_log: u32) -> Level {
        let (w, h) = (1usize << w_log, 1usize << h_log);
        let mut data = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                data[(x << h_log) | y] = self.data[(y << w_log) | x];
            }
        }
        Level {
            x_stride_log: h_log,
            y_stride_log: 0,
            data,
            ..self
        }
    }
}

/// A periodic texture with box-filtered levels reduced independently in x and y (a "ripmap"),
/// for band-limited sampling with anisotropic footprints.
#[derive(Debug)]
pub(crate) struct RipMap {
    nlx: usize,
    nly: usize,
    levels: Vec<Level>,
}

impl RipMap {
    /// Builds all levels from a base texture of `2^w_log x 2^h_log` texels.
    fn new(w_log: u32, h_log: u32, base: Vec<f32>) -> Self {
        let (nlx, nly) = (w_log as usize + 1, h_log as usize + 1);
        let mut levels: Vec<Level> = Vec::with_capacity(nlx * nly);
        for ly in 0..nly {
            for lx in 0..nlx {
                let (lw, lh) = (w_log - lx as u32, h_log - ly as u32);
                let data = if lx == 0 && ly == 0 {
                    base.clone()
                } else if lx > 0 {
                    // Halve horizontally from (lx-1, ly).
                    let src = &levels[ly * nlx + lx - 1];
                    let (w, h) = (1usize << lw, 1usize << lh);
                    let sw = w * 2;
                    (0..w * h)
                        .map(|i| {
                            let (x, y) = (i % w, i / w);
                            0.5 * (src.data[y * sw + 2 * x] + src.data[y * sw + 2 * x + 1])
                        })
                        .collect()
                } else {
                    // Halve vertically from (0, ly-1).
                    let src = &levels[(ly - 1) * nlx];
                    let (w, h) = (1usize << lw, 1usize << lh);
                    (0..w * h)
                        .map(|i| {
                            let (x, y) = (i % w, i / w);
                            0.5 * (src.data[2 * y * w + x] + src.data[(2 * y + 1) * w + x])
                        })
                        .collect()
                };
                levels.push(Level {
                    x_stride_log: 0,
                    y_stride_log: lw,
                    wmask: (1i32 << lw) - 1,
                    hmask: (1i32 << lh) - 1,
                    data,
                });
            }
        }
        RipMap { nlx, nly, levels }
    }

    /// Re-stores every level column-major.
    fn into_column_major(self) -> RipMap {
        let nlx = self.nlx;
        let (w_log, h_log) = ((self.nlx - 1) as u32, (self.nly - 1) as u32);
        let levels = self
            .levels
            .into_iter()
            .enumerate()
            .map(|(i, l)| {
                let (lx, ly) = ((i % nlx) as u32, (i / nlx) as u32);
                l.into_column_major(w_log - lx, h_log - ly)
            })
            .collect();
        RipMap { levels, ..self }
    }

    #[inline(always)]
    fn level(&self, lx: usize, ly: usize) -> &Level {
        let lx = lx.min(self.nlx - 1);
        let ly = ly.min(self.nly - 1);
        &self.levels[ly * self.nlx + lx]
    }
}

/// Level index for a footprint of `fp_texels` base texels (rounded log2, at least 0).
#[inline]
fn level_for(fp_texels: f32) -> usize {
    if fp_texels <= 1.0 {
        0
    } else {
        (fp_texels.log2() + 0.5) as usize
    }
}

/// Wall texel edge, metres (paint speckle of 1.2 cm spans 2 texels).
pub(crate) const WALL_TEXEL_M: f32 = 0.006;
const WALL_LOG_W: u32 = 10; // 1024 texels = 6.144 m along a wall
const WALL_LOG_H: u32 = 9; // 512 texels = 3.072 m up (more than the wall height)
/// Floor/ceiling texel edge, metres (32 texels per floor tile).
pub(crate) const PLANE_TEXEL_M: f32 = FLOOR_TILE_M / 32.0;
const PLANE_LOG: u32 = 9; // 512 texels = 4.8 m = 16 floor tiles = 8 ceiling panels

/// The baked, band-limitable textures shared by all maps (deterministic contents).
#[derive(Debug)]
pub(crate) struct Textures {
    wall: RipMap,
    floor: RipMap,
    ceiling: RipMap,
}

impl Textures {
    /// The process-wide textures, built on first use.
    pub(crate) fn get() -> &'static Textures {
        static TEX: OnceLock<Textures> = OnceLock::new();
        TEX.get_or_init(Textures::build)
    }

    fn build() -> Textures {
        // Wall paint: low-frequency blotches + 4.8 cm mottling + 1.2 cm speckle, periodic.
        let (ww, wh) = (1usize << WALL_LOG_W, 1usize << WALL_LOG_H);
        let wall: Vec<f32> = (0..ww * wh)
            .map(|i| {
                let (x, y) = ((i % ww) as f32 + 0.5, (i / ww) as f32 + 0.5);
                let (s, z) = (x * WALL_TEXEL_M, y * WALL_TEXEL_M);
                WALL_PAINT_MEAN
                    + 16.0 * periodic_vnoise(s / 0.384, z / 0.384, 16, 8, 11)
                    + 22.0 * periodic_vnoise(s / 0.048, z / 0.048, 128, 64, 12)
                    + 28.0 * periodic_vnoise(s / 0.012, z / 0.012, 512, 256, 13)
            })
            .collect();
        // Floor: 16 x 16 tiles of 32 texels, grout 2 texels (1.9 cm), per-tile shade, speckle.
        let n = 1usize << PLANE_LOG;
        let floor: Vec<f32> = (0..n * n)
            .map(|i| {
                let (x, y) = (i % n, i / n);
                let (tx, ty) = ((x / 32) as i32, (y / 32) as i32);
                let (lx, ly) = (x % 32, y % 32);
                let speck = unit(hash3(x as i32, y as i32, 21)) - 0.5;
                if lx == 0 || lx == 31 || ly == 0 || ly == 31 {
                    return 72.0 + 20.0 * speck;
                }
                let (fx, fy) = (x as f32 + 0.5, y as f32 + 0.5);
                140.0
                    + 60.0 * (unit(hash3(tx, ty, 22)) - 0.5)
                    + 28.0 * speck
                    + 14.0 * periodic_vnoise(fx / 4.0, fy / 4.0, 128, 128, 23)
                    + 8.0 * periodic_vnoise(fx / 64.0, fy / 64.0, 8, 8, 24)
            })
            .collect();
        // Ceiling: 8 x 8 panels of 64 texels (0.6 m), T-bars, perforation speckle, and light
        // fixtures (bright with louvre slats) in about one panel in five.
        let ceiling: Vec<f32> = (0..n * n)
            .map(|i| {
                let (x, y) = (i % n, i / n);
                let (px, py) = ((x / 64) as i32, (y / 64) as i32);
                let (lx, ly) = (x % 64, y % 64);
                let ph = hash3(px, py, 31);
                let speck = unit(hash3(x as i32, y as i32, 32)) - 0.5;
                if !(2..62).contains(&lx) || !(2..62).contains(&ly) {
                    return 128.0 + 16.0 * speck;
                }
                let (fx, fy) = (x as f32 + 0.5, y as f32 + 0.5);
                if ph.is_multiple_of(5) && (8..56).contains(&lx) && (8..56).contains(&ly) {
                    let c = if ph & 0x100 == 0 { lx } else { ly };
                    return if c % 8 < 2 { 150.0 } else { 248.0 } + 6.0 * speck;
                }
                186.0
                    + 16.0 * (unit(ph) - 0.5)
                    + 24.0 * speck
                    + 10.0 * periodic_vnoise(fx / 4.0, fy / 4.0, 128, 128, 33)
                    + 8.0 * periodic_vnoise(fx / 32.0, fy / 32.0, 16, 16, 34)
            })
            .collect();
        Textures {
            wall: RipMap::new(WALL_LOG_W, WALL_LOG_H, wall).into_column_major(),
            floor: RipMap::new(PLANE_LOG, PLANE_LOG, floor),
            ceiling: RipMap::new(PLANE_LOG, PLANE_LOG, ceiling),
        }
    }
}

/// Frequency factor of the wall's close-range detail layer.
const DETAIL_SCALE: f32 = 4.0;
/// Pixel footprint below which the detail layer fades in (full at half of it), metres.
const DETAIL_START_FP_M: f32 = 0.0015;

/// Per-column wall texture parameters (constant down a column).
pub(crate) struct WallColumn<'a> {
    /// Coordinate along the wall, metres (world x or y).
    s: f32,
    /// Footprint of one pixel vertically, metres.
    fp_z: f32,
    /// The two paint levels blended trilinearly, their x parts and scales, and the blend weight.
    lv0: &'a Level,
    lv1: &'a Level,
    xp0: XPart,
    xp1: XPart,
    scale0: f32,
    scale1: f32,
    blend: f32,
    /// Vertical texel offset of this wall run.
    z_off: f32,
    /// The decoration under this column, with its horizontal coverages (outer, inner).
    decor: Option<(&'a Decor, f32, f32)>,
    /// Band weight of poster blobs.
    w_decor_fine: f32,
    /// Weight of the close-range detail layer (the paint texture at a quarter of its scale).
    w_detail: f32,
    /// Detail layer's x part.
    xp_detail: XPart,
    /// Contrast of the texture around its mean (1: the texture as it is).
    contrast: f32,
    /// The flat grey the texture's deviations are scaled towards (the run's paint).
    albedo: f32,
}

/// Mean grey level of the wall paint texture (the constant of its formula in
/// `Textures::build`).
pub(crate) const WALL_PAINT_MEAN: f32 = 172.0;
/// Least departure of a wall run's flat paint from [`WALL_PAINT_MEAN`] at zero contrast, grey
/// levels (so that two walls meeting at a corner always differ by twice this).
pub(crate) const PLAIN_PAINT_MIN: f32 = 4.0;
/// Spread of the runs' departures beyond [`PLAIN_PAINT_MIN`], grey levels.
pub(crate) const PLAIN_PAINT_SPREAD: f32 = 10.0;

impl<'a> WallColumn<'a> {
    /// Prepares the column constants for wall coordinate `s`, pixel footprints along the wall
    /// and vertically, the wall run hit, and the wall contrast (`@wall_contrast`, 0..=1):
    /// the texture's deviations from its mean are scaled by it, and the mean moves towards
    /// the run's own flat paint as it falls, reaching it at 0.
    pub(crate) fn new(
        tex: &'a Textures,
        s: f32,
        fp_s: f32,
        fp_z: f32,
        run: Option<&'a WallRun>,
        contrast: f32,
    ) -> Self {
        let contrast = if contrast.is_nan() {
            1.0
        } else {
            contrast.clamp(0.0, 1.0)
        };
        let paint_offset = run.map_or(0.0, |r| r.paint_offset);
        let albedo = WALL_PAINT_MEAN + (1.0 - contrast) * paint_offset;
        let fp = fp_s.max(fp_z);
        let (s_off, z_off) = run.map_or((17.0, 5.0), |r| {
            ((r.seed & 0x3ff) as f32, ((r.seed >> 10) & 0x7f) as f32)
        });
        let lambda = (fp / WALL_TEXEL_M).max(1.0).log2();
        let top = WALL_LOG_H as usize;
        let mut l0 = (lambda as usize).min(top);
        let mut blend = if l0 >= top { 0.0 } else { lambda - l0 as f32 };
        // Snap nearly-pure levels to one sample (saves the second lookup on ~1/8 of columns).
        if blend < 1.0 / 16.0 {
            blend = 0.0;
        } else if blend > 15.0 / 16.0 {
            l0 = (l0 + 1).min(top);
            blend = 0.0;
        }
        let l1 = (l0 + 1).min(top);
        let (lv0, lv1) = (tex.wall.level(l0, l0), tex.wall.level(l1, l1));
        let (scale0, scale1) = (1.0 / (1u32 << l0) as f32, 1.0 / (1u32 << l1) as f32);
        let u = s / WALL_TEXEL_M + s_off;
        let mut decor = None;
        if let Some(run) = run {
            for d in &run.decor {
                if s + fp_s >= d.s0 && s - fp_s <= d.s1 {
                    let cov_outer = interval_cov(s, d.s0, d.s1, fp_s);
                    let inset = match d.kind {
                        DecorKind::Door => DOOR_FRAME_M,
                        DecorKind::Poster { .. } => 0.02,
                    };
                    let cov_inner = interval_cov(s, d.s0 + inset, d.s1 - inset, fp_s);
                    decor = Some((d, cov_outer, cov_inner));
                    break;
                }
            }
        }
        let blob = match decor {
            Some((
                Decor {
                    kind: DecorKind::Poster { blob_m },
                    ..
                },
                _,
                _,
            )) => *blob_m,
            _ => 0.05,
        };
        WallColumn {
            s,
            fp_z,
            lv0,
            lv1,
            xp0: lv0.xpart(u * scale0 - 0.5),
            xp1: lv1.xpart(u * scale1 - 0.5),
            scale0,
            scale1,
            blend,
            z_off,
            decor,
            w_decor_fine: band_weight(blob, fp),
            // Only where one texel spans more than ~4 pixels (closer than ~1 m at f = 640 px).
            w_detail: ((DETAIL_START_FP_M - fp) / (0.5 * DETAIL_START_FP_M)).clamp(0.0, 1.0),
            xp_detail: lv0.xpart(u * DETAIL_SCALE + 301.0),
            contrast,
            albedo,
        }
    }

    /// Grey level of the wall at height `z` (metres) in this column.
    #[inline(always)]
    pub(crate) fn shade(&self, st: &mut ShadeState, noise: &NoiseTable, z: f32) -> f32 {
        if self.contrast >= 1.0 {
            return self.shade_textured(st, noise, z);
        }
        if self.contrast <= 0.0 {
            return self.albedo;
        }
        self.albedo + self.contrast * (self.shade_textured(st, noise, z) - WALL_PAINT_MEAN)
    }

    /// The full-contrast texture (paint, baseboard, doors, posters).
    #[inline(always)]
    fn shade_textured(&self, st: &mut ShadeState, noise: &NoiseTable, z: f32) -> f32 {
        let v_base = z * (1.0 / WALL_TEXEL_M) + self.z_off;
        let a = self
            .lv0
            .sample_x_cached(self.xp0, v_base * self.scale0 - 0.5, &mut st.c0);
        let paint = if self.blend > 0.0 {
            let b = self
                .lv1
                .sample_x_cached(self.xp1, v_base * self.scale1 - 0.5, &mut st.c1);
            lerp(a, b, self.blend)
        } else {
            a
        };
        let paint = if self.w_detail > 0.0 {
            // Close up, the bilinear-magnified paint gets finer self-similar detail.
            let d =
                self.lv0
                    .sample_x_cached(self.xp_detail, v_base * DETAIL_SCALE + 177.0, &mut st.cd);
            paint + self.w_detail * (d - WALL_PAINT_MEAN)
        } else {
            paint
        };
        let mut v = paint;
        if z < BASEBOARD_M + self.fp_z {
            // Dark baseboard with the paint texture's detail at reduced contrast.
            let cov = interval_cov(z, -1.0, BASEBOARD_M, self.fp_z);
            v = lerp(v, 0.8 * paint - 80.0, cov);
        }
        if let Some((d, cov_s_outer, cov_s_inner)) = self.decor
            && z < d.z1 + self.fp_z
            && z > d.z0 - self.fp_z
        {
            match d.kind {
                DecorKind::Door => {
                    let cov_o = cov_s_outer * interval_cov(z, -1.0, d.z1, self.fp_z);
                    v = lerp(v, 0.9 * paint - 105.0, cov_o);
                    let cov_i = cov_s_inner * interval_cov(z, -1.0, d.z1 - DOOR_FRAME_M, self.fp_z);
                    if cov_i > 0.0 {
                        let panel = 1.3 * paint - 110.0 + 20.0 * unit(hash32(d.seed));
                        v = lerp(v, panel, cov_i);
                    }
                }
                DecorKind::Poster { blob_m } => {
                    let cov_o = cov_s_outer * interval_cov(z, d.z0, d.z1, self.fp_z);
                    v = lerp(v, 0.3 * paint + 175.0, cov_o);
                    let cov_i = cov_s_inner * interval_cov(z, d.z0 + 0.02, d.z1 - 0.02, self.fp_z);
                    if cov_i > 0.0 {
                        let sd = d.seed as i32 & 0xff;
                        let inv = 1.0 / blob_m;
                        let s = self.s;
                        let n = noise.at(s * inv, z * inv, sd, sd * 3 + 1)
                            + 0.5
                                * self.w_decor_fine
                                * noise.at(s * inv * 2.3, z * inv * 2.3, sd + 50, sd);
                        let hard = (n * 3.0).clamp(-1.0, 1.0);
                        let content = 98.0
                            + 60.0 * unit(hash32(d.seed))
                            + 105.0 * lerp(0.35 * n, hard, self.w_decor_fine);
                        v = lerp(v, content, cov_i);
                    }
                }
            }
        }
        v
    }
}

/// Per-row floor or ceiling texture parameters (footprint-selected ripmap level).
pub(crate) struct PlaneRow<'a> {
    lv: &'a Level,
    sx: f32,
    sy: f32,
    off_x: f32,
    off_y: f32,
}

impl<'a> PlaneRow<'a> {
    /// Row parameters for the floor (`ceiling == false`) or ceiling, with pixel footprints
    /// `fp_x_m`, `fp_y_m` along world x and y, for the map's decoration seed.
    pub(crate) fn new(
        tex: &'a Textures,
        ceiling: bool,
        fp_x_m: f32,
        fp_y_m: f32,
        seed: u32,
    ) -> Self {
        let lx = level_for(fp_x_m / PLANE_TEXEL_M);
        let ly = level_for(fp_y_m / PLANE_TEXEL_M);
        let map = if ceiling { &tex.ceiling } else { &tex.floor };
        // Offsets are whole tiles/panels (64 texels), so tiles stay on the world's 0.3 m grid.
        let off_x = ((seed & 7) * 64) as f32;
        let off_y = (((seed >> 3) & 7) * 64) as f32;
        PlaneRow {
            lv: map.level(lx, ly),
            sx: 1.0 / (1u32 << lx.min(PLANE_LOG as usize)) as f32,
            sy: 1.0 / (1u32 << ly.min(PLANE_LOG as usize)) as f32,
            off_x,
            off_y,
        }
    }

    /// Grey level at world (x, y) metres; `cache` keeps the last texel quad (consecutive
    /// pixels of a magnified row often share it).
    #[inline(always)]
    pub(crate) fn shade(&self, cache: &mut QuadCache, x: f32, y: f32) -> f32 {
        let u = (x * (1.0 / PLANE_TEXEL_M) + self.off_x) * self.sx - 0.5;
        let v = (y * (1.0 / PLANE_TEXEL_M) + self.off_y) * self.sy - 0.5;
        let (xi, fx) = split(u);
        let (yi, fy) = split(v);
        if xi != cache.xi || yi != cache.yi {
            let lv = self.lv;
            let c0 = ((xi & lv.wmask) as usize) << lv.x_stride_log;
            let c1 = (((xi + 1) & lv.wmask) as usize) << lv.x_stride_log;
            let r0 = ((yi & lv.hmask) as usize) << lv.y_stride_log;
            let r1 = (((yi + 1) & lv.hmask) as usize) << lv.y_stride_log;
            let d = &lv.data;
            cache.q = [d[r0 + c0], d[r0 + c1], d[r1 + c0], d[r1 + c1]];
            cache.xi = xi;
            cache.yi = yi;
        }
        let [a, b, c, d] = cache.q;
        lerp(lerp(a, b, fx), lerp(c, d, fx), fy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_helpers() {
        assert_eq!(interval_cov(0.5, 0.0, 1.0, 0.1), 1.0);
        assert_eq!(interval_cov(2.0, 0.0, 1.0, 0.1), 0.0);
        assert!((interval_cov(1.0, 0.0, 1.0, 0.1) - 0.5).abs() < 1e-6);
        assert_eq!(band_weight(0.012, 0.001), 1.0);
        assert_eq!(band_weight(0.012, 0.012), 0.0);
    }

    #[test]
    fn noise_is_continuous_and_bounded() {
        let t = NoiseTable::get();
        let mut prev = t.at(0.0, 0.3, 0, 0);
        let mut max_step = 0.0f32;
        for i in 1..2000 {
            let v = t.at(i as f32 * 0.01, 0.3, 0, 0);
            assert!((-1.0..=1.0).contains(&v));
            max_step = max_step.max((v - prev).abs());
            prev = v;
        }
        // Bilinear: a step of 0.01 cell changes the value by at most 0.02.
        assert!(max_step <= 0.02 + 1e-5, "{max_step}");
        // Negative coordinates work (floor, not truncation toward zero).
        let a = t.at(-0.999, 0.0, 0, 0);
        let b = t.at(-1.0, 0.0, 0, 0);
        assert!((a - b).abs() < 0.01);
    }
}
