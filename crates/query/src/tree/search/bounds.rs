//! The cheap lower bounds of the tree queries: separating-axis gaps of node pairs from their boxes
//! and the certified support bounds of their leaves, and how far a motion moves a kept bound.

use super::super::warm::CutPair;
use super::super::BodyTree;
use super::TreeQueryParams;
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Matrix3, Real, Vector3};

/// The cheap lower bounds of one query: tree B is seen in tree A's frame (every node of a tree
/// shares the tree's pose).
///
/// For a unit axis `L`, the projections of two sets onto `L` are intervals, and any two points
/// `x ∈ A`, `y ∈ B` satisfy `‖x − y‖ ≥ |L·(x − y)|`; so the gap between the projected intervals
/// of two sets containing the bodies is a lower bound of the bodies' distance (the separating
/// axis test). The sets are the certified support bounds of the leaves below each node
/// ([`BodyTree::support_upper`]: for a compound body, the leaves' convex hull, tighter than the
/// containment fits) and the nodes' boxes; the axis is the direction between the box centers
/// ([`CheapBounds::gap_axis`]), refined towards the witnesses' normal before a leaf pair is
/// solved ([`CheapBounds::refined_gap`]), or the axis a kept cut pair was decided along. The
/// support bounds decide most of the pairs the boxes alone leave to a solve, the leaves' hulls
/// at the parents more still (on chair_101 × human_10 a cold query solves about a fifth of the
/// leaf pairs it would solve with the boxes alone).
pub(crate) struct CheapBounds {
    /// Pose of B's frame in A's frame, `pose_a⁻¹·pose_b`.
    pub(super) rel: Isometry3,
    /// Rotation of B's frame in A's frame.
    pub(super) rot: Matrix3,
    /// Translation of B's frame in A's frame.
    pub(super) shift: Vector3,
    /// Relative slack subtracted from every bound for rounding ([`TreeQueryParams::cheap_slack`]).
    pub(crate) slack: Real,
}

/// A certified lower bound of the distance between two posed convex bodies (meters), from their
/// boxes and certified support bounds along the line between the boxes' centers
/// (`CheapBounds::gap_axis`: the larger of the boxes' projected gap and the separating-axis gap
/// `n·t − h_B(−Rᵀn) − h_A(n)` of [`sublevel_core::poly::SupportBound`], less the default relative
/// slack [`TreeQueryParams::cheap_slack`] of 10⁻¹² for rounding); negative
/// or zero when that axis does not separate them. `None` for a nonconvex body (no certified
/// bound). About 0.14 µs, against about 2 µs for a cold distance solve at 2d = 6.
///
/// On the cold chair_101 / human_10 poses of `sublevel-lab bench` it shows separation (bound > 0) for
/// most of the separated pairs whose bounding spheres overlap (about nine in ten at 2d = 4 to 8);
/// refining the axis towards the witnesses (two support look-ups a round, as the tree queries do)
/// shows no more.
pub fn axis_lower_bound(a: &Body, pose_a: &Isometry3, b: &Body, pose_b: &Isometry3) -> Option<Real> {
    CheapBounds::new(pose_a, pose_b, TreeQueryParams::DEFAULT.cheap_slack).gap_axis(a, 0, b, 0).map(|(gap, _)| gap)
}

impl CheapBounds {
    /// The cheap bounds of the poses `pose_a`, `pose_b` with the relative rounding slack `slack`
    /// ([`TreeQueryParams::cheap_slack`]).
    pub(crate) fn new(pose_a: &Isometry3, pose_b: &Isometry3, slack: Real) -> Self {
        let rel = pose_a.inverse() * pose_b;
        let rot = *rel.rotation.to_rotation_matrix().matrix();
        Self { rot, shift: rel.translation.vector, rel, slack }
    }

    /// Lower bound of the distance between bodies `a` (tree A) and `b` (tree B), meters; negative
    /// when the boxes overlap (then only 0 is a bound); `None` for a nonconvex body (no box).
    #[cfg(test)]
    pub fn gap(&self, a: &Body, b: &Body) -> Option<Real> {
        self.gap_axis(a, 0, b, 0).map(|(g, _)| g)
    }

    /// `CheapBounds::gap` and its axis: the separating-axis gap of nodes `na` of A and `nb` of B
    /// along the direction n between their box centers (A's frame, from A towards B), the best of
    /// their boxes' projections and the certified support bounds of their leaves
    /// ([`CheapBounds::axis_gap`]), slack subtracted. The bound is also a lower bound of the gap
    /// along n, which the motion bounds of a kept cut follow ([`CutPair`]). `None`
    /// for a nonconvex body.
    ///
    /// The boxes' own separating axes (their six face normals) decided almost no pair of
    /// chair_101 × human_10 that n did not, at twice the cost, so they are not tried.
    pub(crate) fn gap_axis<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(
        &self,
        a: &A,
        na: usize,
        b: &B,
        nb: usize,
    ) -> Option<(Real, Vector3)> {
        let (ca, ha) = a.node_box(na)?;
        let (cb, hb) = b.node_box(nb)?;
        let d = self.rot * cb + self.shift - ca;
        let norm = d.norm();
        let n = if norm > 0.0 { d / norm } else { Vector3::x() };
        let m = self.rot.transpose() * n;
        // The boxes' projections on n (contains the bounding spheres' gap ‖d‖ − r_A − r_B, by
        // Cauchy–Schwarz: Σ hₖ |nₖ| ≤ ‖h‖) and the leaves' support bounds along n.
        let boxes = norm - ha.dot(&n.abs()) - hb.dot(&m.abs());
        let g = n.dot(&self.shift) - b.support_upper(nb, &-m)? - a.support_upper(na, &n)?;
        Some((g.max(boxes) - self.slack * (1.0 + norm + g.abs()), n))
    }

    /// The separating-axis gap along an axis refined towards the witnesses' normal: from `start`
    /// (a unit axis, e.g. the pair's normal in an earlier query; zero for the direction between
    /// the box centers), twice `n ← (y − x)/‖y − x‖` with x, y the estimated
    /// support points of A along n and of B along −n ([`sublevel_core::body::Body::support_estimate`]); the best
    /// [`CheapBounds::axis_gap`] of the axes tried, slack subtracted (meters), and its axis.
    /// `None` for a nonconvex body.
    pub(crate) fn refined_gap<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(
        &self,
        a: &A,
        na: usize,
        b: &B,
        nb: usize,
        start: &Vector3,
    ) -> Option<(Real, Vector3)> {
        let (ba, bb) = (a.body(na), b.body(nb));
        let (ca, _) = a.node_box(na)?;
        let (cb, _) = b.node_box(nb)?;
        let d = self.rot * cb + self.shift - ca;
        let mut n = if *start == Vector3::zeros() { d.try_normalize(0.0)? } else { *start };
        let mut best = (Real::NEG_INFINITY, n);
        for _ in 0..2 {
            let x = ba.support_estimate(&n)?;
            let z = bb.support_estimate(&-(self.rot.transpose() * n))?;
            let y = self.rot * z.coords + self.shift;
            n = match (y - x.coords).try_normalize(0.0) {
                Some(m) => m,
                None => break,
            };
            let g = self.axis_gap(a, na, b, nb, &n)?;
            if g > best.0 {
                best = (g, n);
            }
        }
        Some((best.0 - self.slack * (1.0 + d.norm()), best.1))
    }

    /// The separating-axis gap of nodes `na` of A and `nb` of B along the unit axis `n` (A's
    /// frame, meters) from the certified support bounds of their leaves
    /// ([`BodyTree::support_upper`]):
    ///
    /// ```text
    /// min_{y ∈ B} n·y − max_{x ∈ A} n·x = n·t − h_B(−Rᵀn) − h_A(n)     (B posed by (R, t) in A's frame)
    /// ```
    ///
    /// a lower bound of dist(A, B) for every unit n, equal to it at the witnesses' normal (up to
    /// the support table's interpolation). `None` for a nonconvex body. Without slack: callers
    /// subtract their own multiple of [`CheapBounds::slack`].
    #[inline]
    pub(crate) fn axis_gap<A: BodyTree + ?Sized, B: BodyTree + ?Sized>(
        &self,
        a: &A,
        na: usize,
        b: &B,
        nb: usize,
        n: &Vector3,
    ) -> Option<Real> {
        let ha = a.support_upper(na, n)?;
        let hb = b.support_upper(nb, &-(self.rot.transpose() * n))?;
        Some(n.dot(&self.shift) - hb - ha)
    }

    /// How far any point of B within `reach` meters of B's origin moved (A's frame, meters) from
    /// the relative pose `from` to this query's: `‖t − t₀‖ + ‖R − R₀‖₂·reach`, rounding included
    /// ([`FarPairs`](super::super::warm::FarPairs)).
    pub(super) fn displacement(&self, from: &Isometry3, reach: Real) -> Real {
        super::super::warm::displacement(from, &self.rel, reach, self.slack)
    }

    /// The motion of B from the relative pose `from` to this query's, in A's frame: `(R − R₀, t − t₀)`
    /// and `‖R − R₀‖₂ = 2 sin(θ/2)` ([`CutPair`]).
    fn motion_since(&self, from: &Isometry3) -> (Matrix3, Vector3, Real) {
        let turn = self.rot - from.rotation.to_rotation_matrix().matrix();
        // 2 sin(θ/2) = 2 ‖imaginary part‖ of the unit quaternion R R₀⁻¹ (no trigonometry).
        let k = 2.0 * (self.rel.rotation * from.rotation.inverse()).imag().norm();
        (turn, self.shift - from.translation.vector, k.min(2.0))
    }
}

/// The motion of B relative to A since a kept cut's pose, and the bound of how far it moved a
/// cut pair's separating gap ([`CutPair`]).
pub(super) struct Motion {
    /// Rows of (R − R₀)ᵀ, for w = (R − R₀)ᵀ n.
    turn_t: [Vector3; 3],
    /// R − R₀.
    turn: Matrix3,
    /// t − t₀.
    shift: Vector3,
    /// ‖R − R₀‖₂ = 2 sin(θ/2).
    k: Real,
    /// Rounding slack per meter of the terms.
    slack: Real,
}

impl Motion {
    /// The motion from the relative pose `from` to the query's of `cheap`.
    pub(super) fn new(cheap: &CheapBounds, from: &Isometry3) -> Self {
        let (turn, shift, k) = cheap.motion_since(from);
        let turn_t = [turn.column(0).into_owned(), turn.column(1).into_owned(), turn.column(2).into_owned()];
        Self { turn_t, turn, shift, k, slack: cheap.slack * (1.0 + shift.norm()) }
    }

    /// The bound `lower` of pair `p` (at the cut's pose) moved to this query's pose. B's node box
    /// (c, h) moved by (R − R₀)c + t − t₀ at its center; along the pair's axis n the gap moves by
    /// n·((R − R₀)c + t − t₀) = w·c + n·(t − t₀) with w = (R − R₀)ᵀn, less Σ hₖ|wₖ| for the box;
    /// without an axis, by the length (written out: this runs for every kept pair of every warm
    /// query).
    #[inline(always)]
    pub(super) fn moved(&self, p: &CutPair, lower: Real) -> Real {
        let (c, h, n) = (&p.box_b.0, &p.box_b.1, &p.axis);
        let along = if n.x == 0.0 && n.y == 0.0 && n.z == 0.0 {
            -(self.turn * c + self.shift).norm() - self.k * h.norm()
        } else {
            let w = [self.turn_t[0].dot(n), self.turn_t[1].dot(n), self.turn_t[2].dot(n)];
            w[0] * c.x + w[1] * c.y + w[2] * c.z + n.dot(&self.shift)
                - (h.x * w[0].abs() + h.y * w[1].abs() + h.z * w[2].abs())
        };
        lower + along - self.slack * (p.size + lower.abs())
    }
}
