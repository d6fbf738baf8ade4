//! A gap grid over a cloud: for every cell of a uniform grid, a lower bound of the distance from
//! any point of the cell to the cloud's nearest point, so that most of the checks' radius queries
//! ("is some point within ρ of x?") are answered "no" by one load, before the k-d tree.
//!
//! ```text
//! cells     edge h, fixed; cell (i, j, k) spans origin + h·[i, i + 1) × …, the origin the
//!           cloud's box's low corner less ρ_max
//! blocks    8 × 8 × 8 cells, allocated only where the reach of an occupied cell (the box of
//!           its points grown by ρ_max) meets them; found by their block coordinates in a table
//!           of every block of the box grown by ρ_max when it has at most 4 entries per point
//!           (4096 at least), else in a hash map (foldhash)
//! gap(C)    min over occupied cells O within ρ_max of C of dist(C, box(O))², where box(O) is the
//!           bounding box of O's points (≤ dist(C, p)² for each of them), else ρ_max²;
//!           stored as f32 rounded down; a cell in no block: ρ_max² (no point within ρ_max)
//! points    the cells of each occupied block list their own points (a counting sort over the
//!           occupied blocks' cells)
//! query     x in cell C, radius ρ ≤ ρ_max:  gap(C) > ρ²  ⇒  no point within ρ of x
//!           (dist(x, p) ≥ dist(C, p)); else the points of the cells the ball's box meets;
//!           x outside the box  ⇒  every point is farther than ρ_max
//! ```
//!
//! Why blocks: the memory follows what is kept, not the box. A dense grid over the box of two
//! points 10 m apart holds tens of megabytes, and one whose box spans kilometers must grow its cell
//! until it fits, until a cell holds every point and each query scans them all. The cell edge never
//! changes and each occupied cell allocates at most 2 × 2 × 2 blocks of 2 KiB of gaps, plus 2 KiB
//! of point lists for each block holding points; a compact cloud takes about the dense grid's
//! memory. A query is one block look-up (a load from the table, or one hash look-up when the box is
//! too sparse for a table) and one load of the gap: the blocks not allocated all read as one shared
//! block of ρ_max² gaps and no points, so there is no branch between the two loads.
//!
//! The gaps are built by visiting, for every occupied cell, the cells within ρ_max of its points'
//! box: at most (2ρ_max/h + 2)³, 343 at the defaults. A cell's box, not each of its points, keeps
//! the build to a few milliseconds for a room-sized frame (the bounds lose at most the box's
//! extent in the directions of its corners). Queries with a radius above ρ_max go to the coarse
//! level (10 cm cells up to 30 cm, in blocks the same way), then to the k-d tree. The answers are
//! exact: the grid only skips cells no point of which can be within ρ.

use std::collections::HashMap;
use sublevel_core::math::{Real, Vector3};

/// The cell edge (meters).
pub const GRID_CELL: Real = 0.04;

/// The largest gap a cell records (meters): queries with a larger radius go to the tree.
pub const GRID_REACH: Real = 0.1;

/// The cell edge of the coarse grid (meters), which answers the radii up to [`COARSE_REACH`].
pub const COARSE_CELL: Real = 0.1;

/// The largest gap a coarse cell records (meters): the balls of whole links.
pub const COARSE_REACH: Real = 0.3;

/// A block's edge in cells is `1 << BLOCK_BITS`.
const BLOCK_BITS: u32 = 3;

/// A block's edge in cells.
const BLOCK: usize = 1 << BLOCK_BITS;

/// Cells of a block.
const BLOCK_CELLS: usize = BLOCK * BLOCK * BLOCK;

/// The block table's entries allowed per point before the blocks go to a hash map.
const TABLE_PER_POINT: usize = 4;

/// Entries a block table may always have.
const TABLE_FLOOR: usize = 4096;

/// The slot of every block not allocated: a block whose every gap is the reach (squared, rounded
/// down) and whose cells list no points, so that a query loads a gap without a branch.
const FAR: usize = 0;

/// Every stored squared gap is scaled down by a part in 10⁶ (far beyond f32's rounding) so that
/// it stays below the true one.
const DOWN: f32 = 1.0 - 1e-6;

/// Where the allocated blocks lie: block coordinates → slot.
#[derive(Clone, Debug)]
enum Blocks {
    /// An entry for every block of the box (x-major): the slot, [`FAR`] where none.
    Table { dims: [usize; 3], slots: Vec<u32> },
    /// The allocated blocks alone.
    Map(HashMap<[u32; 3], u32, foldhash::fast::FixedState>),
}

impl Blocks {
    /// The blocks of a grid of `cells` cells per axis over `points` points: a table when it has
    /// at most [`TABLE_PER_POINT`] entries per point (or [`TABLE_FLOOR`]), else a hash map.
    fn new(cells: [usize; 3], points: usize) -> Self {
        let dims = cells.map(|c| c.div_ceil(BLOCK));
        let entries = dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]);
        if entries <= TABLE_FLOOR.max(points.saturating_mul(TABLE_PER_POINT)) {
            Self::Table { dims, slots: vec![FAR as u32; entries] }
        } else {
            Self::Map(HashMap::default())
        }
    }

    /// The slot of block `b` (block coordinates within the grid), [`FAR`] when not allocated.
    #[inline(always)]
    fn get(&self, b: [usize; 3]) -> usize {
        match self {
            Self::Table { dims, slots } => slots[(b[0] * dims[1] + b[1]) * dims[2] + b[2]] as usize,
            Self::Map(map) => Self::look_up(map, b),
        }
    }

    /// The slot of block `b` in `map`, [`FAR`] when not allocated (out of line: the table's
    /// look-up stays small where it is inlined).
    #[inline(never)]
    fn look_up(map: &HashMap<[u32; 3], u32, foldhash::fast::FixedState>, b: [usize; 3]) -> usize {
        // Block coordinates fit in u32: a grid spans at most 2·10⁶ m of 4 cm cells.
        map.get(&[b[0] as u32, b[1] as u32, b[2] as u32]).map_or(FAR, |&s| s as usize)
    }

    /// The slot of block `b`, given `next` (> [`FAR`]) when it has none yet: (slot, whether new).
    fn get_or_insert(&mut self, b: [usize; 3], next: usize) -> (usize, bool) {
        let entry = match self {
            Self::Table { dims, slots } => &mut slots[(b[0] * dims[1] + b[1]) * dims[2] + b[2]],
            Self::Map(map) => map.entry(b.map(|v| v as u32)).or_insert(FAR as u32),
        };
        if *entry == FAR as u32 {
            *entry = next as u32;
            (next, true)
        } else {
            (*entry as usize, false)
        }
    }

    /// Bytes held (a hash map's about: key, value and control byte per bucket of capacity).
    fn memory_bytes(&self) -> usize {
        match self {
            Self::Table { slots, .. } => slots.len() * 4,
            Self::Map(map) => map.capacity() * (std::mem::size_of::<([u32; 3], u32)>() + 1),
        }
    }
}

/// Squared gaps of a grid's cells, block by block (module docs): cell `c` of the block in slot
/// `s` at `gaps[s · 512 + local(c)]`, slot [`FAR`] standing for every block not allocated.
#[derive(Clone, Debug)]
struct Gaps {
    /// The low corner of cell (0, 0, 0) (meters).
    origin: Vector3,
    /// The cell edge (meters).
    edge: Real,
    /// Cells along each axis, over the cloud's box grown by the reach.
    dims: [usize; 3],
    blocks: Blocks,
    gaps: Vec<f32>,
    /// The reach squared, rounded down: the gap of every cell in no block.
    far: f32,
}

/// The index of cell `c` within its block: (i · 8 + j) · 8 + k of the low bits, so that a block's
/// rows along z are contiguous.
#[inline]
fn local(c: [usize; 3]) -> usize {
    const MASK: usize = BLOCK - 1;
    ((c[0] & MASK) * BLOCK + (c[1] & MASK)) * BLOCK + (c[2] & MASK)
}

impl Gaps {
    /// No blocks but [`FAR`], over the box from `lo` to `hi` (meters) grown by `reach`, cells of
    /// `edge`, for a cloud of `points` points.
    fn new(lo: &Vector3, hi: &Vector3, edge: Real, reach: Real, points: usize) -> Self {
        let origin = lo.add_scalar(-reach);
        let size = (hi - lo).add_scalar(2.0 * reach);
        let dims = [0, 1, 2].map(|k| (size[k] / edge).ceil().max(1.0) as usize);
        let far = (reach * reach * (1.0 - 1e-6)) as f32;
        Self { origin, edge, dims, blocks: Blocks::new(dims, points), gaps: vec![far; BLOCK_CELLS], far }
    }

    /// The cell holding `x`, or `None` outside the grid.
    #[inline]
    fn cell(&self, x: &Vector3) -> Option<[usize; 3]> {
        let mut out = [0; 3];
        for (k, o) in out.iter_mut().enumerate() {
            let c = (x[k] - self.origin[k]) / self.edge;
            if !(c >= 0.0 && c < self.dims[k] as Real) {
                return None;
            }
            *o = c as usize;
        }
        Some(out)
    }

    /// The cell coordinate of `v` along axis `k`, clamped into the grid.
    #[inline]
    fn clamped(&self, v: Real, k: usize) -> usize {
        // Clamped at 0 first, so that truncation is the floor (and no call to libm's floor).
        ((v - self.origin[k]) / self.edge).clamp(0.0, (self.dims[k] - 1) as Real) as usize
    }

    /// The slot of the block holding cell `c` ([`FAR`] when not allocated).
    #[inline(always)]
    fn slot(&self, c: [usize; 3]) -> usize {
        self.blocks.get([c[0] >> BLOCK_BITS, c[1] >> BLOCK_BITS, c[2] >> BLOCK_BITS])
    }

    /// The squared gap of the cell holding `x` ([`Gaps::far`] outside the grid or any block).
    #[inline]
    fn gap(&self, x: &Vector3) -> f32 {
        match self.cell(x) {
            Some(c) => self.gaps[self.slot(c) * BLOCK_CELLS + local(c)],
            None => self.far,
        }
    }

    /// Slots: the allocated blocks and [`FAR`].
    fn len(&self) -> usize {
        self.gaps.len() / BLOCK_CELLS
    }

    /// The slot of block `b`, allocated (every gap [`Gaps::far`]) when it has none.
    fn block(&mut self, b: [usize; 3]) -> usize {
        let (slot, new) = self.blocks.get_or_insert(b, self.len());
        if new {
            self.gaps.resize(self.gaps.len() + BLOCK_CELLS, self.far);
        }
        slot
    }

    /// Lowers the gap of each cell `c` from `a` to `b` (inclusive, within the grid) to
    /// `(d2[0][c₀ − a₀] + d2[1][c₁ − a₁] + d2[2][c₂ − a₂]) · DOWN` where that is less, allocating
    /// the blocks of the cells it lowers (`d2`: squared axis distances, rounded down).
    fn lower(&mut self, a: [usize; 3], b: [usize; 3], d2: [&[f32]; 3]) {
        // The least of an axis' squared distances over cells lo..=hi.
        let least =
            |k: usize, lo: usize, hi: usize| d2[k][lo - a[k]..=hi - a[k]].iter().copied().fold(f32::MAX, f32::min);
        // The cells of block coordinate `q` along axis k within a..=b.
        let cells = |k: usize, q: usize| (a[k].max(q << BLOCK_BITS), b[k].min(((q + 1) << BLOCK_BITS) - 1));
        for bx in a[0] >> BLOCK_BITS..=b[0] >> BLOCK_BITS {
            let (i0, i1) = cells(0, bx);
            let x2 = least(0, i0, i1);
            for by in a[1] >> BLOCK_BITS..=b[1] >> BLOCK_BITS {
                let (j0, j1) = cells(1, by);
                let y2 = least(1, j0, j1);
                for bz in a[2] >> BLOCK_BITS..=b[2] >> BLOCK_BITS {
                    let (k0, k1) = cells(2, bz);
                    // A block no cell of which it would lower stays unallocated.
                    if (x2 + y2 + least(2, k0, k1)) * DOWN >= self.far {
                        continue;
                    }
                    let base = self.block([bx, by, bz]) * BLOCK_CELLS;
                    let z2 = &d2[2][k0 - a[2]..=k1 - a[2]];
                    for i in i0..=i1 {
                        let x2 = d2[0][i - a[0]];
                        for j in j0..=j1 {
                            let dxy = x2 + d2[1][j - a[1]];
                            if dxy * DOWN >= self.far {
                                continue;
                            }
                            let row = base + local([i, j, k0]);
                            // A select (one `minss`), not `f32::min` and its NaN handling.
                            for (slot, z2) in self.gaps[row..=row + (k1 - k0)].iter_mut().zip(z2) {
                                let g = (dxy + z2) * DOWN;
                                *slot = if g < *slot { g } else { *slot };
                            }
                        }
                    }
                }
            }
        }
    }

    /// Bytes held.
    fn memory_bytes(&self) -> usize {
        self.gaps.len() * std::mem::size_of::<f32>() + self.blocks.memory_bytes()
    }
}

/// A gap grid (module docs).
#[derive(Clone, Debug)]
pub(crate) struct GapGrid {
    /// Squared gaps of the [`GRID_CELL`] cells up to [`GRID_REACH`]; the blocks holding points
    /// take the slots after [`FAR`].
    fine: Gaps,
    /// The slots below it hold points ([`FAR`]'s cells list none).
    occupied: usize,
    /// Cell `c` of the block in slot `s` < `occupied` lists its own points:
    /// `items[starts[s · 512 + local(c)]..starts[s · 512 + local(c) + 1]]`.
    starts: Vec<u32>,
    items: Vec<u32>,
    /// Gaps of 10 cm cells up to 30 cm, from the occupied cells alone ([`coarse`]).
    coarse: Gaps,
}

/// The coarse level of a [`GapGrid`]: squared gaps between 10 cm cells and the nearest occupied
/// one (the distance between the two cells' boxes, a lower bound for any point of either), up to
/// [`COARSE_REACH`], in blocks as the fine level; built from the occupied cells, a few hundred on
/// a MotionBenchMaker scene. `points`, best given cell by cell of the fine grid (consecutive
/// points mostly share their coarse cell, which is then listed once), has `count` points in the
/// box from `lo` to `hi`.
fn coarse<'a>(points: impl Iterator<Item = &'a [Real; 3]>, count: usize, lo: &Vector3, hi: &Vector3) -> Gaps {
    let reach = COARSE_REACH;
    let mut grid = Gaps::new(lo, hi, COARSE_CELL, reach, count);
    let mut occupied: Vec<[usize; 3]> = Vec::new();
    for p in points {
        let c = [0, 1, 2].map(|k| grid.clamped(p[k], k));
        if occupied.last() != Some(&c) {
            occupied.push(c);
        }
    }
    occupied.sort_unstable();
    occupied.dedup();
    // Cells more than ⌈reach / edge⌉ away have whole cells of at least the reach between.
    let span = (reach / grid.edge).ceil() as usize;
    let mut d2: [Vec<f32>; 3] = Default::default();
    for o in &occupied {
        let a = [0, 1, 2].map(|k| o[k].saturating_sub(span));
        let b = [0, 1, 2].map(|k| (o[k] + span).min(grid.dims[k] - 1));
        // Whole cells between the two boxes, per axis.
        for (k, d) in d2.iter_mut().enumerate() {
            d.clear();
            d.extend((a[k]..=b[k]).map(|c| {
                let g = (c.abs_diff(o[k]).saturating_sub(1)) as Real * grid.edge;
                (g * g) as f32 * DOWN
            }));
        }
        grid.lower(a, b, [&d2[0], &d2[1], &d2[2]]);
    }
    grid
}

impl GapGrid {
    /// The grid of `points` (meters), with cells of [`GRID_CELL`] and gaps up to [`GRID_REACH`].
    pub(crate) fn build(points: &[[Real; 3]]) -> Self {
        let reach = GRID_REACH;
        let (mut lo, mut hi) = (Vector3::zeros(), Vector3::zeros());
        if let Some(first) = points.first() {
            (lo, hi) = (Vector3::from(*first), Vector3::from(*first));
        }
        for p in points {
            let v = Vector3::from(*p);
            lo = lo.inf(&v);
            hi = hi.sup(&v);
        }
        let mut fine = Gaps::new(&lo, &hi, GRID_CELL, reach, points.len());
        // Each point's home: its block's slot · 512 + its cell within the block, the blocks that
        // hold points taking the slots after FAR. Consecutive points mostly share their block.
        let mut last: Option<([usize; 3], usize)> = None;
        let home: Vec<u32> = points
            .iter()
            .map(|p| {
                let c = [0, 1, 2].map(|k| fine.clamped(p[k], k));
                let b = c.map(|v| v >> BLOCK_BITS);
                let slot = match last {
                    Some((l, s)) if l == b => s,
                    _ => {
                        let s = fine.block(b);
                        last = Some((b, s));
                        s
                    }
                };
                // At most a block per point and FAR: below (2²⁰ + 1) · 512.
                (slot * BLOCK_CELLS + local(c)) as u32
            })
            .collect();
        let occupied = fine.len();
        // The points sorted by home (a counting sort), so that the gaps below are written block
        // by block. `starts[h]` counts home h's points, then, summed, ends them; placing the
        // points from the last down moves it to where they start.
        let mut starts = vec![0u32; occupied * BLOCK_CELLS + 1];
        for &h in &home {
            starts[h as usize] += 1;
        }
        let mut sum = 0;
        for s in &mut starts {
            sum += *s;
            *s = sum;
        }
        let mut items = vec![0u32; points.len()];
        for (i, &h) in home.iter().enumerate().rev() {
            let s = &mut starts[h as usize];
            *s -= 1;
            items[*s as usize] = i as u32;
        }
        // Squared axis gaps in f32, each rounded down (DOWN), and their sums once more: the
        // stored gaps stay below the true ones.
        let mut d2: [Vec<f32>; 3] = Default::default();
        let mut at = 0;
        while at < items.len() {
            // The box [l, u] of the points of the next occupied cell.
            let first = &points[items[at] as usize];
            let (mut l, mut u) = (*first, *first);
            let h = home[items[at] as usize];
            at += 1;
            while at < items.len() && home[items[at] as usize] == h {
                let q = &points[items[at] as usize];
                for k in 0..3 {
                    l[k] = l[k].min(q[k]);
                    u[k] = u[k].max(q[k]);
                }
                at += 1;
            }
            let a = [0, 1, 2].map(|k| fine.clamped(l[k] - reach, k));
            let b = [0, 1, 2].map(|k| fine.clamped(u[k] + reach, k));
            // The squared axis gaps between the box and the cells of each axis' range.
            for (k, d) in d2.iter_mut().enumerate() {
                d.clear();
                d.extend((a[k]..=b[k]).map(|c| {
                    let start = fine.origin[k] + c as Real * fine.edge;
                    let g = (start - u[k]).max(l[k] - (start + fine.edge)).max(0.0);
                    (g * g) as f32 * DOWN
                }));
            }
            fine.lower(a, b, [&d2[0], &d2[1], &d2[2]]);
        }
        let coarse = coarse(items.iter().map(|&i| &points[i as usize]), points.len(), &lo, &hi);
        Self { fine, occupied, starts, items, coarse }
    }

    /// Whether the grid shows that no point lies within `radius` of `x` (false: it cannot tell).
    #[inline]
    pub(crate) fn clear(&self, x: &Vector3, radius: Real) -> bool {
        if self.items.is_empty() {
            return true;
        }
        if radius > GRID_REACH {
            return radius <= COARSE_REACH && self.coarse.gap(x) as Real > radius * radius;
        }
        self.fine.gap(x) as Real > radius * radius
    }

    /// Calls `f(point index)` for the points of the cells that the box of the ball (`x`,
    /// `radius`) meets, until `f` returns true; false when the grid cannot tell (a radius above
    /// [`GRID_REACH`]), true otherwise.
    #[inline]
    fn scan(&self, x: &Vector3, radius: Real, mut f: impl FnMut(usize) -> bool) -> bool {
        if self.items.is_empty() {
            return true;
        }
        if radius > GRID_REACH {
            return false;
        }
        let g = &self.fine;
        // Outside the grid: every point is farther than the reach.
        let Some(c) = g.cell(x) else { return true };
        if g.gaps[g.slot(c) * BLOCK_CELLS + local(c)] as Real > radius * radius {
            return true;
        }
        let range = |k: usize| {
            let lo = ((x[k] - radius - g.origin[k]) / g.edge).floor().max(0.0) as usize;
            let hi = (((x[k] + radius - g.origin[k]) / g.edge).floor() as usize).min(g.dims[k] - 1);
            (lo, hi)
        };
        let ((l0, h0), (l1, h1), (l2, h2)) = (range(0), range(1), range(2));
        let (lo, hi) = ([l0, l1, l2], [h0, h1, h2]);
        // The cells of block coordinate `q` along axis k within the range.
        let cells = |k: usize, q: usize| (lo[k].max(q << BLOCK_BITS), hi[k].min(((q + 1) << BLOCK_BITS) - 1));
        for bx in lo[0] >> BLOCK_BITS..=hi[0] >> BLOCK_BITS {
            for by in lo[1] >> BLOCK_BITS..=hi[1] >> BLOCK_BITS {
                for bz in lo[2] >> BLOCK_BITS..=hi[2] >> BLOCK_BITS {
                    // Only the slots after FAR and below `occupied` hold points.
                    let s = g.blocks.get([bx, by, bz]);
                    if s == FAR || s >= self.occupied {
                        continue;
                    }
                    let base = s * BLOCK_CELLS;
                    let ((i0, i1), (j0, j1), (k0, k1)) = (cells(0, bx), cells(1, by), cells(2, bz));
                    for i in i0..=i1 {
                        for j in j0..=j1 {
                            // The cells of one row along z are adjacent in `items`.
                            let row = base + local([i, j, k0]);
                            let (from, to) = (self.starts[row] as usize, self.starts[row + (k1 - k0) + 1] as usize);
                            for &p in &self.items[from..to] {
                                if f(p as usize) {
                                    return true;
                                }
                            }
                        }
                    }
                }
            }
        }
        true
    }

    /// Whether some point of `points` (the grid's) lies within `radius` ≤ [`GRID_REACH`] of `x`:
    /// `Some` with the answer, `None` for a larger radius (the grid cannot tell).
    #[inline]
    pub(crate) fn any_within(&self, points: &[[Real; 3]], x: &Vector3, radius: Real) -> Option<bool> {
        let r2 = radius * radius;
        let mut found = false;
        let told = self.scan(x, radius, |i| {
            let p = &points[i];
            let (dx, dy, dz) = (p[0] - x.x, p[1] - x.y, p[2] - x.z);
            found = dx * dx + dy * dy + dz * dz <= r2;
            found
        });
        told.then_some(found)
    }

    /// Appends to `out` the points of `points` (the grid's) within `radius` ≤ [`GRID_REACH`] of
    /// `x` and returns true; false for a larger radius (nothing appended: the grid cannot tell).
    pub(crate) fn within(&self, points: &[[Real; 3]], x: &Vector3, radius: Real, out: &mut Vec<usize>) -> bool {
        let r2 = radius * radius;
        self.scan(x, radius, |i| {
            let p = &points[i];
            let (dx, dy, dz) = (p[0] - x.x, p[1] - x.y, p[2] - x.z);
            if dx * dx + dy * dy + dz * dz <= r2 {
                out.push(i);
            }
            false
        })
    }

    /// Bytes the grid holds: the gaps of both levels, their block tables, the point lists.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.fine.memory_bytes() + self.coarse.memory_bytes() + (self.starts.len() + self.items.len()) * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// The distance from `x` to the nearest of `points` (∞ when none), by brute force.
    fn nearest(points: &[[Real; 3]], x: &Vector3) -> Real {
        points.iter().map(|p| (Vector3::from(*p) - x).norm()).fold(Real::INFINITY, Real::min)
    }

    /// Asserts that `grid`'s answers about `(x, r)` agree with the brute force over `points`:
    /// `clear` only where no point lies within r, `any_within` and `within` exactly. Returns
    /// whether `clear` answered.
    fn agrees(grid: &GapGrid, points: &[[Real; 3]], x: &Vector3, r: Real) -> bool {
        let near = nearest(points, x);
        let cleared = grid.clear(x, r);
        assert!(!cleared || near > r, "cleared {x:?} r {r} with a point at {near}");
        let brute = points.iter().any(|p| (Vector3::from(*p) - x).norm_squared() <= r * r);
        match grid.any_within(points, x, r) {
            Some(found) => assert_eq!(found, brute, "{x:?} r {r}: nearest {near}"),
            None => assert!(r > GRID_REACH),
        }
        let mut found = Vec::new();
        if grid.within(points, x, r, &mut found) {
            found.sort_unstable();
            let all: Vec<usize> =
                (0..points.len()).filter(|&i| (Vector3::from(points[i]) - x).norm_squared() <= r * r).collect();
            assert_eq!(found, all, "{x:?} r {r}");
        } else {
            assert!(r > GRID_REACH && found.is_empty());
        }
        cleared
    }

    /// `n` points uniform in the box `center ± half` (meters).
    fn cluster(rng: &mut StdRng, n: usize, center: Vector3, half: Vector3) -> Vec<[Real; 3]> {
        (0..n)
            .map(|_| {
                let v = center + Vector3::from_fn(|k, _| rng.random_range(-half[k]..half[k]));
                [v.x, v.y, v.z]
            })
            .collect()
    }

    #[test]
    fn clear_answers_never_contradict_brute_force() {
        let mut rng = StdRng::seed_from_u64(3);
        let points: Vec<[Real; 3]> = (0..2000)
            .map(|_| [rng.random_range(0.0..0.5), rng.random_range(-0.3..0.3), rng.random_range(0.0..0.02)])
            .collect();
        let grid = GapGrid::build(&points);
        // A compact cloud's blocks are found through a table.
        assert!(matches!(grid.fine.blocks, Blocks::Table { .. }));
        let mut cleared = 0;
        for _ in 0..20_000 {
            let x = Vector3::new(rng.random_range(-0.3..0.8), rng.random_range(-0.6..0.6), rng.random_range(-0.3..0.3));
            let r = rng.random_range(0.0..0.35);
            let near = nearest(&points, &x);
            if grid.clear(&x, r) {
                assert!(near > r, "cleared {x:?} r {r} with a point at {near}");
                cleared += 1;
            }
        }
        // It answers most of the far queries.
        assert!(cleared > 6_000, "{cleared}");
        for _ in 0..20_000 {
            let x = Vector3::new(rng.random_range(-0.3..0.8), rng.random_range(-0.6..0.6), rng.random_range(-0.3..0.3));
            agrees(&grid, &points, &x, rng.random_range(0.0..0.12));
        }
        assert!(GapGrid::build(&[]).clear(&Vector3::zeros(), 1.0));
    }

    #[test]
    fn far_clusters_answer_exactly_in_memory_proportional_to_the_points() {
        // Two clusters of 1500 points, 0.5 m across, at ±9.9e5 m on every axis: a box of
        // 2·10⁶ m a side, which a dense grid of 4 cm cells could not hold.
        let mut rng = StdRng::seed_from_u64(7);
        let (a, b) = (Vector3::repeat(9.9e5), Vector3::repeat(-9.9e5));
        let half = Vector3::new(0.25, 0.25, 0.1);
        let mut points = cluster(&mut rng, 1500, a, half);
        points.extend(cluster(&mut rng, 1500, b, half));
        let grid = GapGrid::build(&points);
        assert!(matches!(grid.fine.blocks, Blocks::Map(_)));
        let bytes = grid.memory_bytes();
        assert!(bytes < 1 << 20, "{bytes} bytes for {} points", points.len());
        // The cells keep their edge: a query scans the points of the cells about it alone (a
        // 2 cm ball's box meets at most 2 × 2 × 2 cells of 4 cm, each a few points), not a cloud.
        let mut scanned = 0;
        assert!(grid.scan(&a, 0.02, |_| {
            scanned += 1;
            false
        }));
        assert!(scanned > 0 && scanned < 100, "{scanned} points scanned");
        let mut cleared = 0;
        for k in 0..20_000 {
            let center = if k % 2 == 0 { a } else { b };
            let x = center + Vector3::from_fn(|_, _| rng.random_range(-0.6..0.6));
            if agrees(&grid, &points, &x, rng.random_range(0.0..0.35)) {
                cleared += 1;
            }
        }
        assert!(cleared > 5_000, "{cleared}");
    }

    #[test]
    fn two_points_ten_meters_apart_hold_little() {
        let points = [[0.0, 0.0, 0.0], [10.0, 10.0, 10.0]];
        let grid = GapGrid::build(&points);
        // Each point: at most 8 blocks of fine gaps and 8 of coarse ones (2 KiB each), and the
        // point lists of its own block (2 KiB); the dense grid held 31 MB.
        let bytes = grid.memory_bytes();
        assert!(bytes < 80_000, "{bytes} bytes");
        let mut rng = StdRng::seed_from_u64(11);
        for k in 0..4000 {
            let x = Vector3::from(points[k % 2]) + Vector3::from_fn(|_, _| rng.random_range(-0.4..0.4));
            agrees(&grid, &points, &x, rng.random_range(0.0..0.35));
        }
    }

    #[test]
    fn queries_far_outside_any_block_answer_clear() {
        let mut rng = StdRng::seed_from_u64(13);
        let mut points = cluster(&mut rng, 500, Vector3::zeros(), Vector3::repeat(0.2));
        points.extend(cluster(&mut rng, 500, Vector3::repeat(50.0), Vector3::repeat(0.2)));
        let grid = GapGrid::build(&points);
        let empty = |x: &Vector3| {
            // Within the box, between the clusters (no block there), and outside the box.
            for r in [0.0, 0.05, 0.099, 0.2, 0.299] {
                assert!(grid.clear(x, r), "{x:?} r {r}");
                assert!(agrees(&grid, &points, x, r));
            }
            assert!(grid.fine.cell(x).is_none_or(|c| grid.fine.slot(c) == FAR));
        };
        for _ in 0..1000 {
            empty(&Vector3::from_fn(|_, _| rng.random_range(5.0..45.0)));
            empty(&Vector3::from_fn(|_, _| rng.random_range(60.0..1e5)));
            empty(&Vector3::from_fn(|_, _| rng.random_range(-1e5..-1.0)));
        }
        // Beyond the coarse reach the grid cannot tell.
        assert!(!grid.clear(&Vector3::repeat(25.0), 0.31));
    }
}
