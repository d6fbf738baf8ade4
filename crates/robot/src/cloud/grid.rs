//! A gap grid over a cloud: for every cell of a uniform grid, a lower bound of the distance from
//! any point of the cell to the cloud's nearest point, so that most of the checks' radius queries
//! ("is some point within ρ of x?") are answered "no" by one load, before the k-d tree.
//!
//! ```text
//! cells     edge h, over the cloud's box grown by ρ_max on every side; each lists its own points
//!           (a counting sort)
//! gap(C)    min over occupied cells O within ρ_max of C of dist(C, box(O))², where box(O) is the
//!           bounding box of O's points (≤ dist(C, p)² for each of them), else ρ_max²;
//!           stored as f32 rounded down
//! query     x in cell C, radius ρ ≤ ρ_max:  gap(C) > ρ²  ⇒  no point within ρ of x
//!           (dist(x, p) ≥ dist(C, p)); else the points of the cells the ball's box meets;
//!           x outside the grid  ⇒  every point is farther than ρ_max
//! ```
//!
//! The gaps are built by visiting, for every occupied cell, the cells within ρ_max of its points'
//! box: at most (2ρ_max/h + 2)³, 343 at the defaults. A cell's box, not each of its points, keeps
//! the build to a few milliseconds for a room-sized frame (the bounds lose at most the box's
//! extent in the directions of its corners). Queries with a radius above ρ_max go to the k-d tree.
//! The answers are exact: the grid only skips cells no point of which can be within ρ.

use sublevel_core::math::{Real, Vector3};

/// The cell edge (meters).
pub const GRID_CELL: Real = 0.04;

/// The largest gap a cell records (meters): queries with a larger radius go to the tree.
pub const GRID_REACH: Real = 0.1;

/// The cell edge of the coarse grid (meters), which answers the radii up to [`COARSE_REACH`].
pub const COARSE_CELL: Real = 0.1;

/// The largest gap a coarse cell records (meters): the balls of whole links.
pub const COARSE_REACH: Real = 0.3;

/// Most cells a grid may have; past it the cell edge grows until the grid fits.
const MAX_CELLS: usize = 1 << 22;

/// A gap grid (module docs).
#[derive(Clone, Debug)]
pub(crate) struct GapGrid {
    origin: Vector3,
    edge: Real,
    dims: [usize; 3],
    /// Squared gaps, rounded down.
    gaps: Vec<f32>,
    /// Cell `c`'s own points: `items[starts[c]..starts[c + 1]]`.
    starts: Vec<u32>,
    items: Vec<u32>,
    /// Gaps of 10 cm cells up to 30 cm, from the occupied cells alone (module docs).
    coarse: Coarse,
}

/// The coarse level of a [`GapGrid`]: squared gaps between 10 cm cells and the nearest occupied
/// one (the distance between the two cells' boxes, a lower bound for any point of either), up to
/// [`COARSE_REACH`]; built from the occupied cells, a few hundred on a MotionBenchMaker scene.
#[derive(Clone, Debug, Default)]
struct Coarse {
    origin: Vector3,
    edge: Real,
    dims: [usize; 3],
    gaps: Vec<f32>,
}

impl Coarse {
    /// The coarse gaps of `points`, best given cell by cell of the fine grid (consecutive points
    /// mostly share their coarse cell, which is then listed once).
    fn build<'a>(points: impl Iterator<Item = &'a [Real; 3]>, lo: &Vector3, hi: &Vector3) -> Self {
        let reach = COARSE_REACH;
        let origin = lo.add_scalar(-reach);
        let size = (hi - lo).add_scalar(2.0 * reach);
        let mut edge = COARSE_CELL;
        let dims = loop {
            let d = size.map(|s| (s / edge).ceil().max(1.0) as usize);
            if d.x.saturating_mul(d.y).saturating_mul(d.z) <= MAX_CELLS {
                break [d.x, d.y, d.z];
            }
            edge *= 2.0;
        };
        // Clamped at 0 first, so that truncation is the floor (and no call to libm's floor).
        let cell = |v: Real, k: usize| ((v - origin[k]) / edge).clamp(0.0, (dims[k] - 1) as Real) as usize;
        let mut occupied: Vec<[usize; 3]> = Vec::new();
        for p in points {
            let c = [cell(p[0], 0), cell(p[1], 1), cell(p[2], 2)];
            if occupied.last() != Some(&c) {
                occupied.push(c);
            }
        }
        occupied.sort_unstable();
        occupied.dedup();
        let r2 = reach * reach;
        // ρ_max² rounded down too: f32(0.09) lies above 0.09.
        let mut gaps = vec![(r2 * (1.0 - 1e-6)) as f32; dims[0] * dims[1] * dims[2]];
        // Cells more than ⌈reach / edge⌉ away have whole cells of at least the reach between.
        let span = (reach / edge).ceil() as usize;
        let between = |a: usize, b: usize| (a.abs_diff(b).saturating_sub(1)) as Real * edge;
        let mut dz2 = Vec::new();
        for o in &occupied {
            let range = |k: usize| o[k].saturating_sub(span)..=(o[k] + span).min(dims[k] - 1);
            // Whole cells between the two boxes, per axis.
            let zs = range(2);
            dz2.clear();
            dz2.extend(zs.clone().map(|k| between(k, o[2]).powi(2)));
            for i in range(0) {
                let dx = between(i, o[0]);
                for j in range(1) {
                    let dy = between(j, o[1]);
                    let dxy = dx * dx + dy * dy;
                    let row = (i * dims[1] + j) * dims[2];
                    for (slot, z2) in gaps[row + zs.start()..=row + zs.end()].iter_mut().zip(&dz2) {
                        *slot = slot.min(((dxy + z2) * (1.0 - 1e-6)) as f32);
                    }
                }
            }
        }
        Self { origin, edge, dims, gaps }
    }

    /// Whether no point lies within `radius` ≤ [`COARSE_REACH`] of `x` by the coarse gaps.
    #[inline]
    fn clear(&self, x: &Vector3, radius: Real) -> bool {
        let mut index = 0;
        for k in 0..3 {
            let c = (x[k] - self.origin[k]) / self.edge;
            if !(c >= 0.0 && c < self.dims[k] as Real) {
                return radius < COARSE_REACH;
            }
            index = index * self.dims[k] + c as usize;
        }
        self.gaps[index] as Real > radius * radius
    }
}

impl GapGrid {
    /// The grid of `points` (meters), with cells of [`GRID_CELL`] or larger and gaps up to
    /// [`GRID_REACH`].
    pub(crate) fn build(points: &[[Real; 3]]) -> Self {
        let reach = GRID_REACH;
        if points.is_empty() {
            return Self {
                origin: Vector3::zeros(),
                edge: 1.0,
                dims: [0; 3],
                gaps: Vec::new(),
                starts: Vec::new(),
                items: Vec::new(),
                coarse: Coarse::default(),
            };
        }
        let mut lo = Vector3::repeat(Real::INFINITY);
        let mut hi = Vector3::repeat(Real::NEG_INFINITY);
        for p in points {
            let v = Vector3::from(*p);
            lo = lo.inf(&v);
            hi = hi.sup(&v);
        }
        let origin = lo.add_scalar(-reach);
        let size = (hi - lo).add_scalar(2.0 * reach);
        let mut edge = GRID_CELL;
        let dims = loop {
            let d = size.map(|s| (s / edge).ceil().max(1.0) as usize);
            if d.x.saturating_mul(d.y).saturating_mul(d.z) <= MAX_CELLS {
                break [d.x, d.y, d.z];
            }
            edge *= 2.0;
        };
        let cells = dims[0] * dims[1] * dims[2];
        let r2 = reach * reach;
        // ρ_max² rounded down, as every gap.
        let mut gaps = vec![(r2 * (1.0 - 1e-6)) as f32; cells];
        // Clamped at 0 first, so that truncation is the floor (and no call to libm's floor).
        let cell_of = |v: Real, k: usize| ((v - origin[k]) / edge).clamp(0.0, (dims[k] - 1) as Real) as usize;
        // Each point's own cell, then the points sorted by cell (a counting sort), so that the
        // gaps below are written in the grid's order.
        // `starts[c]` counts cell c's points, then, summed, ends them; placing the points from
        // the last down moves it to where they start (no second array of the grid's size).
        let mut starts = vec![0u32; cells + 1];
        let home: Vec<u32> = points
            .iter()
            .map(|p| {
                let c = (cell_of(p[0], 0) * dims[1] + cell_of(p[1], 1)) * dims[2] + cell_of(p[2], 2);
                starts[c] += 1;
                c as u32
            })
            .collect();
        let mut sum = 0;
        for s in &mut starts {
            sum += *s;
            *s = sum;
        }
        let mut items = vec![0u32; points.len()];
        for (i, &c) in home.iter().enumerate().rev() {
            let s = &mut starts[c as usize];
            *s -= 1;
            items[*s as usize] = i as u32;
        }
        // Squared axis gaps in f32, each scaled down by a part in 10⁶ (far beyond f32's rounding),
        // and their sums scaled down once more: the stored gaps stay below the true ones.
        const DOWN: f32 = 1.0 - 1e-6;
        let (mut dx2, mut dy2, mut dz2): (Vec<f32>, Vec<f32>, Vec<f32>) = (Vec::new(), Vec::new(), Vec::new());
        let r2f = r2 as f32;
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
            let a = [cell_of(l[0] - reach, 0), cell_of(l[1] - reach, 1), cell_of(l[2] - reach, 2)];
            let b = [cell_of(u[0] + reach, 0), cell_of(u[1] + reach, 1), cell_of(u[2] + reach, 2)];
            // The squared axis gaps between the box and the cells of each axis' range.
            for (k, d2) in [&mut dx2, &mut dy2, &mut dz2].into_iter().enumerate() {
                d2.clear();
                d2.extend((a[k]..=b[k]).map(|c| {
                    let start = origin[k] + c as Real * edge;
                    let g = (start - u[k]).max(l[k] - (start + edge)).max(0.0);
                    (g * g) as f32 * DOWN
                }));
            }
            for (i, x2) in (a[0]..=b[0]).zip(&dx2) {
                for (j, y2) in (a[1]..=b[1]).zip(&dy2) {
                    let dxy = x2 + y2;
                    if dxy > r2f {
                        continue;
                    }
                    let row = (i * dims[1] + j) * dims[2];
                    // A select (one `minss`), not `f32::min` and its NaN handling.
                    for (slot, z2) in gaps[row + a[2]..=row + b[2]].iter_mut().zip(&dz2) {
                        let g = (dxy + z2) * DOWN;
                        *slot = if g < *slot { g } else { *slot };
                    }
                }
            }
        }
        let coarse = Coarse::build(items.iter().map(|&i| &points[i as usize]), &lo, &hi);
        Self { origin, edge, dims, gaps, starts, items, coarse }
    }

    /// The cell coordinates holding `x`, or `None` outside the grid.
    #[inline]
    fn coords(&self, x: &Vector3) -> Option<[usize; 3]> {
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

    #[inline]
    fn index(&self, c: [usize; 3]) -> usize {
        (c[0] * self.dims[1] + c[1]) * self.dims[2] + c[2]
    }

    /// Whether the grid shows that no point lies within `radius` of `x` (false: it cannot tell).
    #[inline]
    pub(crate) fn clear(&self, x: &Vector3, radius: Real) -> bool {
        if self.gaps.is_empty() {
            return true;
        }
        if radius > GRID_REACH {
            return radius <= COARSE_REACH && self.coarse.clear(x, radius);
        }
        match self.coords(x) {
            // Outside the grid: every point is farther than the reach.
            None => radius < GRID_REACH,
            Some(c) => self.gaps[self.index(c)] as Real > radius * radius,
        }
    }

    /// Calls `f(point index)` for the points of the cells that the box of the ball (`x`,
    /// `radius`) meets, until `f` returns true; false when the grid cannot tell (a radius above
    /// [`GRID_REACH`]), true otherwise.
    #[inline]
    fn scan(&self, x: &Vector3, radius: Real, mut f: impl FnMut(usize) -> bool) -> bool {
        if self.gaps.is_empty() {
            return true;
        }
        if radius > GRID_REACH {
            return false;
        }
        let Some(c) = self.coords(x) else { return true };
        if self.gaps[self.index(c)] as Real > radius * radius {
            return true;
        }
        let range = |k: usize| {
            let lo = ((x[k] - radius - self.origin[k]) / self.edge).floor().max(0.0) as usize;
            let hi = (((x[k] + radius - self.origin[k]) / self.edge).floor() as usize).min(self.dims[k] - 1);
            lo..=hi
        };
        for i in range(0) {
            for j in range(1) {
                let row = (i * self.dims[1] + j) * self.dims[2];
                let ks = range(2);
                let (from, to) = (self.starts[row + ks.start()] as usize, self.starts[row + ks.end() + 1] as usize);
                // The cells of one row are adjacent in `items`.
                for &p in &self.items[from..to] {
                    if f(p as usize) {
                        return true;
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

    /// Bytes the grid holds.
    pub(crate) fn memory_bytes(&self) -> usize {
        (self.gaps.len() + self.coarse.gaps.len()) * std::mem::size_of::<f32>()
            + (self.starts.len() + self.items.len()) * 4
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn clear_answers_never_contradict_brute_force() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let points: Vec<[Real; 3]> = (0..2000)
            .map(|_| [rng.random_range(0.0..0.5), rng.random_range(-0.3..0.3), rng.random_range(0.0..0.02)])
            .collect();
        let grid = GapGrid::build(&points);
        let mut cleared = 0;
        for _ in 0..20_000 {
            let x = Vector3::new(rng.random_range(-0.3..0.8), rng.random_range(-0.6..0.6), rng.random_range(-0.3..0.3));
            let r = rng.random_range(0.0..0.35);
            let nearest = points.iter().map(|p| (Vector3::from(*p) - x).norm()).fold(Real::INFINITY, Real::min);
            if grid.clear(&x, r) {
                assert!(nearest > r, "cleared {x:?} r {r} with a point at {nearest}");
                cleared += 1;
            }
        }
        // It answers most of the far queries.
        assert!(cleared > 6_000, "{cleared}");
        for _ in 0..20_000 {
            let x = Vector3::new(rng.random_range(-0.3..0.8), rng.random_range(-0.6..0.6), rng.random_range(-0.3..0.3));
            let r = rng.random_range(0.0..0.12);
            let brute = points.iter().any(|p| (Vector3::from(*p) - x).norm_squared() <= r * r);
            match grid.any_within(&points, &x, r) {
                Some(found) => assert_eq!(found, brute),
                None => assert!(r > GRID_REACH),
            }
            let mut found = Vec::new();
            if grid.within(&points, &x, r, &mut found) {
                found.sort_unstable();
                let all: Vec<usize> =
                    (0..points.len()).filter(|&i| (Vector3::from(points[i]) - x).norm_squared() <= r * r).collect();
                assert_eq!(found, all);
            }
        }
        assert!(GapGrid::build(&[]).clear(&Vector3::zeros(), 1.0));
    }
}
