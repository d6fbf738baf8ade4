//! A gap grid over a cloud: for every cell of a uniform grid, a lower bound of the distance from
//! any point of the cell to the cloud's nearest point, so that most of the checks' radius queries
//! ("is some point within ρ of x?") are answered "no" by one load, before the k-d tree.
//!
//! ```text
//! cells     edge h, over the cloud's box grown by ρ_max on every side; each lists its own points
//!           (a counting sort)
//! gap(C)    min over points p within ρ_max of C of dist(C, p)²  (the box's distance), else ρ_max²
//!           stored as f32 rounded down
//! query     x in cell C, radius ρ ≤ ρ_max:  gap(C) > ρ²  ⇒  no point within ρ of x
//!           (dist(x, p) ≥ dist(C, p)); else the points of the cells the ball's box meets;
//!           x outside the grid  ⇒  every point is farther than ρ_max
//! ```
//!
//! The gaps are built by visiting, for every point, the cells within ρ_max of it: at most
//! (2ρ_max/h + 1)³, 216 at the defaults. Queries with a radius above ρ_max go to the k-d tree.
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
    fn build(points: &[[Real; 3]], lo: &Vector3, hi: &Vector3) -> Self {
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
        let cell = |v: Real, k: usize| ((v - origin[k]) / edge).floor().clamp(0.0, (dims[k] - 1) as Real) as usize;
        let mut occupied: Vec<[usize; 3]> =
            points.iter().map(|p| [cell(p[0], 0), cell(p[1], 1), cell(p[2], 2)]).collect();
        occupied.sort_unstable();
        occupied.dedup();
        let r2 = reach * reach;
        let mut gaps = vec![r2 as f32; dims[0] * dims[1] * dims[2]];
        let span = (reach / edge).ceil() as usize + 1;
        for o in &occupied {
            let range = |k: usize| o[k].saturating_sub(span)..=(o[k] + span).min(dims[k] - 1);
            // Whole cells between the two boxes, per axis.
            let between = |a: usize, b: usize| (a.abs_diff(b).saturating_sub(1)) as Real * edge;
            for i in range(0) {
                let dx = between(i, o[0]);
                for j in range(1) {
                    let dy = between(j, o[1]);
                    let row = (i * dims[1] + j) * dims[2];
                    for k in range(2) {
                        let dz = between(k, o[2]);
                        let g = ((dx * dx + dy * dy + dz * dz) * (1.0 - 1e-6)) as f32;
                        let slot = &mut gaps[row + k];
                        if g < *slot {
                            *slot = g;
                        }
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
        let mut gaps = vec![r2 as f32; cells];
        let cell_of = |v: Real, k: usize| ((v - origin[k]) / edge).floor().clamp(0.0, (dims[k] - 1) as Real) as usize;
        let mut counts = vec![0u32; cells + 1];
        let mut home = Vec::with_capacity(points.len());
        for p in points {
            let a = [cell_of(p[0] - reach, 0), cell_of(p[1] - reach, 1), cell_of(p[2] - reach, 2)];
            let b = [cell_of(p[0] + reach, 0), cell_of(p[1] + reach, 1), cell_of(p[2] + reach, 2)];
            for i in a[0]..=b[0] {
                let dx = axis_gap(p[0], origin[0] + i as Real * edge, edge);
                for j in a[1]..=b[1] {
                    let dy = axis_gap(p[1], origin[1] + j as Real * edge, edge);
                    let row = (i * dims[1] + j) * dims[2];
                    let dxy = dx * dx + dy * dy;
                    if dxy > r2 {
                        continue;
                    }
                    for k in a[2]..=b[2] {
                        let dz = axis_gap(p[2], origin[2] + k as Real * edge, edge);
                        // Rounded down: a part in 10⁶ below, far beyond f32's rounding.
                        let g = ((dxy + dz * dz) * (1.0 - 1e-6)) as f32;
                        let slot = &mut gaps[row + k];
                        if g < *slot {
                            *slot = g;
                        }
                    }
                }
            }
            let c = (cell_of(p[0], 0) * dims[1] + cell_of(p[1], 1)) * dims[2] + cell_of(p[2], 2);
            counts[c + 1] += 1;
            home.push(c as u32);
        }
        for c in 0..cells {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; points.len()];
        for (i, &c) in home.iter().enumerate() {
            items[fill[c as usize] as usize] = i as u32;
            fill[c as usize] += 1;
        }
        let coarse = Coarse::build(points, &lo, &hi);
        Self { origin, edge, dims, gaps, starts: counts, items, coarse }
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

/// The distance along one axis from `v` to the cell interval `[start, start + edge]`.
#[inline(always)]
fn axis_gap(v: Real, start: Real, edge: Real) -> Real {
    (start - v).max(v - (start + edge)).max(0.0)
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
