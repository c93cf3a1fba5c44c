//! Random maze maps (`hvs sim maze`): rooms and corridors joined by doorways, with loops,
//! dead ends and free-standing pillars, in the text format of [`crate::map`].
//!
//! # Layout
//!
//! The map is a lattice of `rooms_x` x `rooms_y` square *slots* of [`SLOT_CELLS`] cells
//! (2.45 m), between walls [`WALL_CELLS`] cells thick (0.35 m), on cells of [`CELL_M`]
//! (0.175 m, so that doorways of 0.7, 0.875 and 1.05 m are whole cells). The default 4 x 4
//! slots make 66 x 66 cells, 11.55 m square, the size of `config/maps/maze.txt`.
//!
//! * Which slots connect: a random spanning tree of the slot lattice (every slot reachable),
//!   plus extra connections that close loops (about one per five slots, at least one from
//!   3x3 slots up: a 2x2 lattice's one spare edge joins the tree's two ends, one of them the
//!   kept dead end, so a 2x2 maze has no loop).
//! * Each connection is a doorway 0.7, 0.875 or 1.05 m wide in the middle of the wall
//!   between the two slots; one connection between two rooms may instead take the whole wall
//!   away (one larger room).
//! * A slot is a *room* (all floor; some with a free-standing pillar 0.35 or 0.525 m square at
//!   least 0.7 m from its walls) or a *corridor* slot: corridors as wide as their doorways
//!   run from each doorway to the slot's middle and meet there (straight, L, T or cross
//!   junctions). One leaf of the tree is always a corridor slot, so the maze has a dead end:
//!   a corridor 2.1 m deep behind its doorway.
//! * The robot starts in a room, at the floor cell farthest from any wall (at least 0.45 m
//!   clear: the robot's turning circle is 0.27 m), facing the way with the longest run of
//!   floor ahead (through a doorway when one lines up).
//!
//! Everything is drawn from [`crate::defects::sim_rng`] of the seed: the same seed gives the
//! same map, different seeds different maps.

use std::fmt::Write as _;

use rand::Rng;

use crate::defects::{SimRng, sim_rng};

/// Cell edge of a generated maze, metres.
pub const CELL_M: f64 = 0.175;
/// Edge of a slot (room or corridor slot) in cells (2.45 m).
pub const SLOT_CELLS: usize = 14;
/// Thickness of the walls between slots and around the maze in cells (0.35 m).
pub const WALL_CELLS: usize = 2;
/// Doorway widths in cells: 0.7, 0.875 and 1.05 m.
pub const DOOR_CELLS: [usize; 3] = [4, 5, 6];
/// Most slots along either side of the maze.
pub const MAX_ROOMS: usize = 16;
/// Clearance of a pillar from its room's walls in cells (0.7 m).
const PILLAR_CLEARANCE_CELLS: usize = 4;
/// Length of a dead-end corridor inside its slot in cells (2.1 m).
const DEAD_END_CELLS: usize = SLOT_CELLS - 2;
/// Least clearance of the start from any wall, metres.
pub const START_CLEARANCE_M: f64 = 0.45;
/// Mixed into the seed so that a maze's draws are not those of the images' noise.
const MAZE_STREAM: u64 = 0x6d61_7a65_5eed_0001;

/// What to generate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MazeOptions {
    /// The seed: the same seed gives the same maze.
    pub seed: u64,
    /// Slots from west to east (2..=[`MAX_ROOMS`]).
    pub rooms_x: usize,
    /// Slots from north to south (2..=[`MAX_ROOMS`]).
    pub rooms_y: usize,
}

impl Default for MazeOptions {
    /// Seed 0, 4 x 4 slots (11.55 m square).
    fn default() -> Self {
        Self {
            seed: 0,
            rooms_x: 4,
            rooms_y: 4,
        }
    }
}

/// Why a maze cannot be generated.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MazeError {
    /// The slot counts are out of range or do not parse.
    #[error("rooms {text:?}: {reason}")]
    Rooms {
        /// What was given.
        text: String,
        /// What is wrong with it.
        reason: String,
    },
}

impl MazeOptions {
    /// Parses `WxH` (slots across and down, e.g. `4x4`) into `(rooms_x, rooms_y)`.
    pub fn parse_rooms(text: &str) -> Result<(usize, usize), MazeError> {
        let err = |reason: &str| MazeError::Rooms {
            text: text.to_string(),
            reason: reason.to_string(),
        };
        let (w, h) = text
            .split_once(['x', 'X'])
            .ok_or_else(|| err("expected WxH, e.g. 4x4"))?;
        let n = |s: &str| {
            s.trim()
                .parse::<usize>()
                .map_err(|_| err("expected WxH, e.g. 4x4"))
        };
        let rooms = (n(w)?, n(h)?);
        Self::check_rooms(rooms).map_err(|reason| err(&reason))?;
        Ok(rooms)
    }

    fn check_rooms((w, h): (usize, usize)) -> Result<(), String> {
        if !(2..=MAX_ROOMS).contains(&w) || !(2..=MAX_ROOMS).contains(&h) {
            return Err(format!("each side must be 2 to {MAX_ROOMS} rooms"));
        }
        Ok(())
    }

    /// Edge of the maze along x in cells.
    pub fn width_cells(&self) -> usize {
        WALL_CELLS + self.rooms_x * (SLOT_CELLS + WALL_CELLS)
    }

    /// Edge of the maze along y in cells.
    pub fn height_cells(&self) -> usize {
        WALL_CELLS + self.rooms_y * (SLOT_CELLS + WALL_CELLS)
    }
}

/// What a slot became.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlotKind {
    /// All floor (perhaps with a pillar).
    Room,
    /// Corridors from its doorways to its middle, the rest wall.
    Corridor,
}

/// A rectangle of cells, in text coordinates (column from the west, row from the top line).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellRect {
    /// First column.
    pub col: usize,
    /// First text row (0 = the northernmost line).
    pub row: usize,
    /// Columns.
    pub cols: usize,
    /// Rows.
    pub rows: usize,
}

/// A doorway through the wall between two slots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Doorway {
    /// The floor cells of the doorway (through the whole wall).
    pub cells: CellRect,
    /// Whether the doorway's width runs along x (a doorway in a wall that runs east-west,
    /// between a slot and the one south of it).
    pub across_x: bool,
}

impl Doorway {
    /// Width of the opening in cells.
    pub fn width_cells(&self) -> usize {
        if self.across_x {
            self.cells.cols
        } else {
            self.cells.rows
        }
    }

    /// Width of the opening in metres.
    pub fn width_m(&self) -> f64 {
        self.width_cells() as f64 * CELL_M
    }
}

/// Compass side of a slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// North (up in the text).
    North,
    /// East.
    East,
    /// South.
    South,
    /// West.
    West,
}

/// A dead end: a corridor with a single doorway.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeadEnd {
    /// The corridor's floor inside its slot.
    pub cells: CellRect,
    /// The side its doorway is on (every other side of `cells` is wall).
    pub open: Side,
}

/// A generated maze.
#[derive(Debug, Clone, PartialEq)]
pub struct Maze {
    /// The options it was made with.
    pub options: MazeOptions,
    /// The map text ([`crate::GridMap::parse`] reads it).
    pub text: String,
    /// Each slot's kind, row-major from the north-west.
    pub slots: Vec<SlotKind>,
    /// Every doorway.
    pub doorways: Vec<Doorway>,
    /// Every free-standing pillar.
    pub pillars: Vec<CellRect>,
    /// Every dead-end corridor.
    pub dead_ends: Vec<DeadEnd>,
    /// Independent loops of the slot graph (connections beyond a spanning tree).
    pub loops: usize,
    /// Slots merged pairwise into one room (the wall between them taken away).
    pub merged: usize,
}

/// A connection between two neighbouring slots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Link {
    /// A doorway this many cells wide.
    Door(usize),
    /// No wall at all (two rooms made one).
    Open,
}

/// An edge of the slot lattice: slot `a` and its east (`east`) or south neighbour `b`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Edge {
    a: usize,
    b: usize,
    east: bool,
}

fn below(rng: &mut SimRng, n: usize) -> usize {
    if n <= 1 {
        0
    } else {
        (rng.next_u64() % n as u64) as usize
    }
}

fn chance(rng: &mut SimRng, p: f64) -> bool {
    ((rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64) < p
}

fn shuffle<T>(rng: &mut SimRng, v: &mut [T]) {
    for i in (1..v.len()).rev() {
        v.swap(i, below(rng, i + 1));
    }
}

fn find(parent: &mut [usize], mut x: usize) -> usize {
    while parent[x] != x {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    x
}

/// The grid being carved: `true` is floor; rows from the top.
struct Grid {
    w: usize,
    floor: Vec<bool>,
}

impl Grid {
    fn carve(&mut self, r: CellRect) {
        for row in r.row..r.row + r.rows {
            for col in r.col..r.col + r.cols {
                self.floor[row * self.w + col] = true;
            }
        }
    }

    fn fill(&mut self, r: CellRect) {
        for row in r.row..r.row + r.rows {
            for col in r.col..r.col + r.cols {
                self.floor[row * self.w + col] = false;
            }
        }
    }

    /// Whether (col, row) is floor; outside the grid is wall.
    fn is_floor(&self, col: i64, row: i64) -> bool {
        if col < 0 || row < 0 || col >= self.w as i64 {
            return false;
        }
        self.floor
            .get(row as usize * self.w + col as usize)
            .copied()
            .unwrap_or(false)
    }
}

fn rect(col: usize, row: usize, cols: usize, rows: usize) -> CellRect {
    CellRect {
        col,
        row,
        cols,
        rows,
    }
}

/// Top-left cell of slot column `i` or row `j`.
fn slot_origin(i: usize) -> usize {
    WALL_CELLS + i * (SLOT_CELLS + WALL_CELLS)
}

/// First cell of a centred span of `w` cells along a slot side.
fn door_offset(w: usize) -> usize {
    (SLOT_CELLS - w) / 2
}

/// Generates a maze.
pub fn generate_maze(options: &MazeOptions) -> Result<Maze, MazeError> {
    let (nx, ny) = (options.rooms_x, options.rooms_y);
    MazeOptions::check_rooms((nx, ny)).map_err(|reason| MazeError::Rooms {
        text: format!("{nx}x{ny}"),
        reason,
    })?;
    let mut rng = sim_rng(options.seed ^ MAZE_STREAM);
    let n = nx * ny;
    let mut edges = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let a = j * nx + i;
            if i + 1 < nx {
                edges.push(Edge {
                    a,
                    b: a + 1,
                    east: true,
                });
            }
            if j + 1 < ny {
                edges.push(Edge {
                    a,
                    b: a + nx,
                    east: false,
                });
            }
        }
    }
    // A random spanning tree (Kruskal over shuffled edges).
    shuffle(&mut rng, &mut edges);
    let mut parent: Vec<usize> = (0..n).collect();
    let (mut tree, mut rest) = (Vec::new(), Vec::new());
    for e in edges {
        let (ra, rb) = (find(&mut parent, e.a), find(&mut parent, e.b));
        if ra == rb {
            rest.push(e);
        } else {
            parent[ra] = rb;
            tree.push(e);
        }
    }
    let degree = |links: &[Edge], s: usize| links.iter().filter(|e| e.a == s || e.b == s).count();
    let start = below(&mut rng, n);
    let leaves: Vec<usize> = (0..n)
        .filter(|&s| s != start && degree(&tree, s) == 1)
        .collect();
    let dead_end = leaves.get(below(&mut rng, leaves.len())).copied();
    // Extra connections (loops), none touching the dead end.
    let want_extra = (n / 5).max(1);
    let mut links = tree;
    let mut extra = 0;
    for e in rest {
        if extra == want_extra {
            break;
        }
        if Some(e.a) == dead_end || Some(e.b) == dead_end {
            continue;
        }
        links.push(e);
        extra += 1;
    }
    let mut kinds = vec![SlotKind::Corridor; n];
    for (s, kind) in kinds.iter_mut().enumerate() {
        if s == start || (Some(s) != dead_end && chance(&mut rng, 0.45)) {
            *kind = SlotKind::Room;
        }
    }
    let mut link_kind: Vec<Link> = links
        .iter()
        .map(|_| Link::Door(DOOR_CELLS[below(&mut rng, DOOR_CELLS.len())]))
        .collect();
    // Perhaps one larger room: the wall between two rooms taken away.
    let room_pairs: Vec<usize> = (0..links.len())
        .filter(|&k| kinds[links[k].a] == SlotKind::Room && kinds[links[k].b] == SlotKind::Room)
        .collect();
    let mut merged = 0;
    if !room_pairs.is_empty() && chance(&mut rng, 0.5) {
        link_kind[room_pairs[below(&mut rng, room_pairs.len())]] = Link::Open;
        merged = 1;
    }

    let (w, h) = (options.width_cells(), options.height_cells());
    let mut grid = Grid {
        w,
        floor: vec![false; w * h],
    };
    // The doorway (or open wall) of each link, and each slot's doorway spans per side.
    let mut sides: Vec<[Option<(usize, usize)>; 4]> = vec![[None; 4]; n];
    let mut doorways = Vec::new();
    for (e, link) in links.iter().zip(&link_kind) {
        let (ia, ja) = (e.a % nx, e.a / nx);
        let (x0, y0) = (slot_origin(ia), slot_origin(ja));
        let (off, width) = match *link {
            Link::Door(d) => (door_offset(d), d),
            Link::Open => (0, SLOT_CELLS),
        };
        let cells = if e.east {
            rect(x0 + SLOT_CELLS, y0 + off, WALL_CELLS, width)
        } else {
            rect(x0 + off, y0 + SLOT_CELLS, width, WALL_CELLS)
        };
        grid.carve(cells);
        if let Link::Door(_) = link {
            doorways.push(Doorway {
                cells,
                across_x: !e.east,
            });
        }
        let (side_a, side_b) = if e.east {
            (Side::East, Side::West)
        } else {
            (Side::South, Side::North)
        };
        sides[e.a][side_a as usize] = Some((off, width));
        sides[e.b][side_b as usize] = Some((off, width));
    }
    let mut dead_ends = Vec::new();
    for s in 0..n {
        let (x0, y0) = (slot_origin(s % nx), slot_origin(s / nx));
        match kinds[s] {
            SlotKind::Room => grid.carve(rect(x0, y0, SLOT_CELLS, SLOT_CELLS)),
            SlotKind::Corridor => {
                let strips = corridor_strips(&sides[s]);
                for (r, _) in &strips {
                    grid.carve(rect(x0 + r.col, y0 + r.row, r.cols, r.rows));
                }
                if let [(r, side)] = strips[..] {
                    dead_ends.push(DeadEnd {
                        cells: rect(x0 + r.col, y0 + r.row, r.cols, r.rows),
                        open: side,
                    });
                }
            }
        }
    }
    // Pillars: some rooms get one; at least one maze-wide.
    let rooms: Vec<usize> = (0..n).filter(|&s| kinds[s] == SlotKind::Room).collect();
    let mut pillars = Vec::new();
    for &s in &rooms {
        if chance(&mut rng, 0.6) {
            pillars.push(place_pillar(&mut rng, s, nx));
        }
    }
    if pillars.is_empty()
        && let Some(&s) = rooms.get(below(&mut rng, rooms.len()))
    {
        pillars.push(place_pillar(&mut rng, s, nx));
    }
    for p in &pillars {
        grid.fill(*p);
    }
    let (start_col, start_row) = start_cell(&grid, start, nx);
    let marker = start_heading(&grid, start_col, start_row);
    let loops = links.len() + 1 - n;
    let mut text = String::new();
    let _ = writeln!(
        text,
        "; generated by `hvs sim maze --seed {} --rooms {nx}x{ny}`: rooms {} ({} with a pillar, pairs merged {merged}), corridor slots {}, doorways {}, loops {loops}, dead ends {}",
        options.seed,
        rooms.len(),
        pillars.len(),
        n - rooms.len(),
        doorways.len(),
        dead_ends.len()
    );
    let _ = writeln!(
        text,
        "; {:.2} m x {:.2} m; doorways 0.7 to 1.05 m wide; walls 0.35 m thick",
        w as f64 * CELL_M,
        h as f64 * CELL_M
    );
    let _ = writeln!(text, "@name maze-{}", options.seed);
    let _ = writeln!(text, "@cell_m {CELL_M}");
    for row in 0..h {
        for col in 0..w {
            text.push(if (col, row) == (start_col, start_row) {
                marker
            } else if grid.is_floor(col as i64, row as i64) {
                '.'
            } else {
                '#'
            });
        }
        text.push('\n');
    }
    Ok(Maze {
        options: *options,
        text,
        slots: kinds,
        doorways,
        pillars,
        dead_ends,
        loops,
        merged,
    })
}

/// The floor strips of a corridor slot (slot-local cells) with the side each strip opens on,
/// from its doorway spans per side (indexed by [`Side`]).
fn corridor_strips(sides: &[Option<(usize, usize)>; 4]) -> Vec<(CellRect, Side)> {
    let s = SLOT_CELLS;
    let get = |side: Side| sides[side as usize];
    let hull = |a: Option<(usize, usize)>, b: Option<(usize, usize)>| match (a, b) {
        (Some((o1, w1)), Some((o2, w2))) => Some((o1.min(o2), (o1 + w1).max(o2 + w2))),
        (Some((o, w)), None) | (None, Some((o, w))) => Some((o, o + w)),
        (None, None) => None,
    };
    // Spans across the slot of the north-south corridors (columns) and east-west (rows).
    let v = hull(get(Side::North), get(Side::South));
    let hz = hull(get(Side::East), get(Side::West));
    let single = sides.iter().flatten().count() == 1;
    let mut out = Vec::new();
    if let Some((o, w)) = get(Side::North) {
        let end = match hz {
            Some((_, h1)) => h1,
            None if single => DEAD_END_CELLS,
            None => s,
        };
        out.push((rect(o, 0, w, end), Side::North));
    }
    if let Some((o, w)) = get(Side::South) {
        let begin = match hz {
            Some((h0, _)) => h0,
            None if single => s - DEAD_END_CELLS,
            None => 0,
        };
        out.push((rect(o, begin, w, s - begin), Side::South));
    }
    if let Some((o, w)) = get(Side::West) {
        let end = match v {
            Some((_, v1)) => v1,
            None if single => DEAD_END_CELLS,
            None => s,
        };
        out.push((rect(0, o, end, w), Side::West));
    }
    if let Some((o, w)) = get(Side::East) {
        let begin = match v {
            Some((v0, _)) => v0,
            None if single => s - DEAD_END_CELLS,
            None => 0,
        };
        out.push((rect(begin, o, s - begin, w), Side::East));
    }
    if let (Some((v0, v1)), Some((h0, h1))) = (v, hz) {
        out.push((rect(v0, h0, v1 - v0, h1 - h0), Side::North));
    }
    out
}

/// A pillar 2 or 3 cells square (0.35 or 0.525 m) in room slot `s`, at least
/// [`PILLAR_CLEARANCE_CELLS`] from the slot's edges.
fn place_pillar(rng: &mut SimRng, s: usize, nx: usize) -> CellRect {
    let size = 2 + below(rng, 2);
    let span = SLOT_CELLS - 2 * PILLAR_CLEARANCE_CELLS - size + 1;
    let (x0, y0) = (slot_origin(s % nx), slot_origin(s / nx));
    rect(
        x0 + PILLAR_CLEARANCE_CELLS + below(rng, span),
        y0 + PILLAR_CLEARANCE_CELLS + below(rng, span),
        size,
        size,
    )
}

/// The start marker at a cell: facing the way (east, north, west, south) with the longest run
/// of floor ahead, the first on a tie.
fn start_heading(grid: &Grid, col: usize, row: usize) -> char {
    let run = |dc: i64, dr: i64| {
        let mut k = 0;
        while grid.is_floor(col as i64 + (k + 1) * dc, row as i64 + (k + 1) * dr) {
            k += 1;
        }
        k
    };
    let mut best = ('>', run(1, 0));
    for (ch, dc, dr) in [('^', 0, -1), ('<', -1, 0), ('v', 0, 1)] {
        let k = run(dc, dr);
        if k > best.1 {
            best = (ch, k);
        }
    }
    best.0
}

/// The start cell in room slot `s`: the floor cell of the slot farthest from any wall cell
/// (ties to the one nearest the slot's middle).
fn start_cell(grid: &Grid, s: usize, nx: usize) -> (usize, usize) {
    let (x0, y0) = (slot_origin(s % nx), slot_origin(s / nx));
    let reach = 4i64;
    let mid = (SLOT_CELLS as f64 - 1.0) / 2.0;
    let mut best = ((x0, y0), f64::NEG_INFINITY, f64::INFINITY);
    for row in y0..y0 + SLOT_CELLS {
        for col in x0..x0 + SLOT_CELLS {
            if !grid.is_floor(col as i64, row as i64) {
                continue;
            }
            // Distance (in cells) from this cell's centre to the nearest wall cell's square.
            let mut clear = (reach as f64) + 0.5;
            for dr in -reach..=reach {
                for dc in -reach..=reach {
                    let (c, r) = (col as i64 + dc, row as i64 + dr);
                    if !grid.is_floor(c, r) {
                        let gx = (dc.abs() as f64 - 0.5).max(0.0);
                        let gy = (dr.abs() as f64 - 0.5).max(0.0);
                        clear = clear.min(gx.hypot(gy));
                    }
                }
            }
            let off = (col - x0) as f64 - mid;
            let off_r = (row - y0) as f64 - mid;
            let centre = off.hypot(off_r);
            if clear > best.1 + 1e-9 || ((clear - best.1).abs() <= 1e-9 && centre < best.2) {
                best = ((col, row), clear, centre);
            }
        }
    }
    best.0
}

#[cfg(test)]
mod tests;
