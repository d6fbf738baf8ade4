//! Sphere trees of link meshes: nested balls that together hold every triangle of a mesh, the
//! first stage of the configuration checks ([`crate::check`]).
//!
//! ```text
//! mesh M = triangles T_1 … T_m, cut by longest-edge bisection into pieces P_1 … P_n
//!          (every edge ≤ the leaf radius ρ; a triangle is the union of its pieces)
//! tree:    every node a ball B(c, r); a node's ball holds every piece below it
//!          (a piece lies in a ball ⇔ its three vertices do); a leaf's ball has r ≤ ρ or one piece
//! so for any closed set O and padding p ≥ 0:
//!     every leaf is below a node with dist(c, O) − r > p   ⇒   every triangle is farther than p
//!                                                              from O
//! ```
//!
//! A mesh checker (coal, FCL, parry's triangle BVH) calls a link and an obstacle in contact when a
//! triangle comes within the padding, so a pair whose descent prunes every branch is free for it
//! too: the tree proves a pair **free**, never colliding, and misses nothing. A descent that
//! reaches a leaf within the padding proves nothing (the pair goes on to the sos bound and the
//! mesh). With a threshold `t ≥ p` in place of `p` the same descent shows that the mesh is
//! farther than `t`, which prunes pairs of a distance query. Two trees prove a self pair free by
//! a dual descent: two balls farther apart than the padding, or a split of the larger one.
//!
//! **Why pieces.** The Panda's meshes hold triangles up to 28 cm long: a ball holding a whole
//! triangle is as large, and a set of 1 024 such balls decided no more pairs than 16 did
//! (`crates/lab/examples/check_profile.rs`). Bisecting the long edges keeps every leaf small
//! where the mesh is, at a few thousand pieces per link.
//!
//! **Building.** Pieces are sorted into a binary tree by the median of their centroids along the
//! longest side of the centroids' box; a node's ball is centered on its pieces' box, its radius
//! the largest vertex distance plus a slack of 1e-9 × (1 + scale), so that each node holds its
//! pieces by construction; [`SphereTree::uncovered_triangle`] checks it independently, and the
//! build checks every mesh vertex ([`SphereTree::covers`]). The
//! Panda reads in 0.25 s with its 11 trees, 0.1 s without them (about 0.4 s with the inner balls
//! of [`crate::inner`] as well).
//!
//! **Distances.** A ball against a primitive is the primitive's signed distance to the ball's
//! center (its own frame) less the radius ([`primitive_signed_distance`]: closed forms for the
//! box, sphere, cylinder, capsule and halfspace).

use sublevel_core::math::{Matrix3, Point3, Real, Vector3};
use sublevel_core::primitive::Primitive;

/// The leaf radius ρ of a link mesh's sphere tree (meters): leaves are at most this large, and
/// pieces are bisected until no edge is longer.
pub const DEFAULT_LEAF_RADIUS: Real = 0.005;

/// Most pieces one mesh is cut into: past it the leaf radius is doubled until the pieces fit.
pub const MAX_PIECES: usize = 200_000;

/// Depth bound of a tree: a median split halves the pieces, so 2⁶⁰ pieces would be needed to
/// exceed it; it sizes the descents' fixed stacks.
pub(crate) const MAX_DEPTH: usize = 60;

/// Leaves a descent against a primitive may find undecided (within the threshold, not wholly
/// within the padding) while it goes on looking for a node that proves contact.
pub const PROOF_LEAVES: usize = 8;

/// What a sphere tree shows of a pair ([`SphereTree::against_primitive`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TreeAnswer {
    /// Every piece is farther than the threshold: the pair is free (and farther than it).
    Apart,
    /// A node's whole ball, hence a part of a triangle, lies within the padding: the pair
    /// collides as a mesh checker decides it.
    Touches,
    /// Neither.
    Unknown,
}

/// A ball: center and radius (meters), in the frame of the mesh it bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Center, meters.
    pub center: Vector3,
    /// Radius, meters (≥ 0).
    pub radius: Real,
}

/// One node of a [`SphereTree`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphereNode {
    /// The ball holding every piece below this node.
    pub sphere: Sphere,
    /// Index of the first of its two children (the second follows it); 0 for a leaf (the root,
    /// index 0, is nobody's child).
    pub children: u32,
}

/// A mesh's sphere tree (module docs): node 0 is the root; empty for an empty mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SphereTree {
    /// The nodes, root first; children are adjacent.
    pub nodes: Vec<SphereNode>,
    /// The leaf radius the tree was built with (meters).
    pub leaf_radius: Real,
}

/// A piece of a triangle: its three vertices.
type Piece = [Vector3; 3];

impl SphereTree {
    /// The sphere tree of the mesh `vertices` / `triangles` (meters; indices validated by the
    /// caller) with leaves of radius at most `leaf_radius` (> 0; doubled until the mesh is cut
    /// into at most [`MAX_PIECES`] pieces).
    pub fn build(vertices: &[Point3], triangles: &[[u32; 3]], leaf_radius: Real) -> Self {
        let mut rho = leaf_radius.max(1e-6);
        let mut pieces = Vec::new();
        while !cut(vertices, triangles, rho, &mut pieces) {
            rho *= 2.0;
        }
        let mut tree = SphereTree { nodes: Vec::new(), leaf_radius: rho };
        if pieces.is_empty() {
            return tree;
        }
        let centroid = |p: &Piece| (p[0] + p[1] + p[2]) / 3.0;
        tree.nodes.push(SphereNode { sphere: ball(&pieces), children: 0 });
        let mut work = vec![(0usize, 0usize, pieces.len())];
        while let Some((node, lo, hi)) = work.pop() {
            let range = &mut pieces[lo..hi];
            if range.len() == 1 || tree.nodes[node].sphere.radius <= rho {
                continue;
            }
            let (mut a, mut b) = (Vector3::repeat(Real::INFINITY), Vector3::repeat(Real::NEG_INFINITY));
            for p in range.iter() {
                let c = centroid(p);
                a = a.inf(&c);
                b = b.sup(&c);
            }
            let axis = (b - a).imax();
            let mid = range.len() / 2;
            range.select_nth_unstable_by(mid, |x, y| centroid(x)[axis].total_cmp(&centroid(y)[axis]));
            let first = tree.nodes.len();
            tree.nodes[node].children = first as u32;
            tree.nodes.push(SphereNode { sphere: ball(&pieces[lo..lo + mid]), children: 0 });
            tree.nodes.push(SphereNode { sphere: ball(&pieces[lo + mid..hi]), children: 0 });
            work.push((first, lo, lo + mid));
            work.push((first + 1, lo + mid, hi));
        }
        tree
    }

    /// The leaves' balls.
    pub fn leaves(&self) -> impl Iterator<Item = &Sphere> + '_ {
        self.nodes.iter().filter(|n| n.children == 0).map(|n| &n.sphere)
    }

    /// Whether the point `x` (the mesh's frame) lies in a leaf's ball and in the balls of all
    /// that leaf's ancestors: what the descents rely on for every point of the mesh.
    pub fn covers(&self, x: &Vector3) -> bool {
        let inside = |k: u32| {
            let s = &self.nodes[k as usize].sphere;
            (x - s.center).norm() <= s.radius
        };
        if self.nodes.is_empty() || !inside(0) {
            return false;
        }
        let mut stack = vec![0u32];
        while let Some(k) = stack.pop() {
            let c = self.nodes[k as usize].children;
            if c == 0 {
                return true;
            }
            stack.extend([c, c + 1].into_iter().filter(|&j| inside(j)));
        }
        false
    }

    /// The first triangle (index) with a point the tree does not cover ([`SphereTree::covers`]),
    /// or `None`: brute force and independent of the build, on the triangle's barycentric grid
    /// of `samples` (≥ 1) steps per edge, its vertices included.
    pub fn uncovered_triangle(&self, vertices: &[Point3], triangles: &[[u32; 3]], samples: usize) -> Option<usize> {
        let n = samples.max(1);
        triangles.iter().position(|t| {
            let [a, b, c] = t.map(|i| vertices[i as usize].coords);
            (0..=n).any(|i| {
                (0..=n - i).any(|j| {
                    let (u, v) = (i as Real / n as Real, j as Real / n as Real);
                    !self.covers(&(a + (b - a) * u + (c - a) * v))
                })
            })
        })
    }

    /// Whether every piece of the tree, its centers mapped by `x ↦ r·x + t` into the primitive
    /// `p`'s frame, is farther than `threshold` from `p` (meters, ≥ 0), with a hair for rounding.
    /// `false` for an empty tree.
    pub fn apart_from_primitive(&self, r: &Matrix3, t: &Vector3, p: &Primitive, threshold: Real) -> bool {
        self.against_primitive(r, t, p, threshold, Real::NEG_INFINITY) == TreeAnswer::Apart
    }

    /// Whether every piece of the tree, its centers mapped by `x ↦ r·x + t` into another shape's
    /// frame, is farther than `threshold` (meters, ≥ 0) from that shape, given `lower(x)`, a lower
    /// bound of the distance from point `x` to the shape (any value ≤ 0 where it has none): a
    /// node is dropped once `lower(center) − radius` exceeds the threshold. `false` for an empty
    /// tree, or when some leaf is not dropped.
    pub fn apart_by(&self, r: &Matrix3, t: &Vector3, threshold: Real, lower: impl Fn(&Vector3) -> Real) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let mut stack = [0u32; MAX_DEPTH + 2];
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let node = &self.nodes[stack[len] as usize];
            if lower(&(r * node.sphere.center + t)) - node.sphere.radius > threshold + 1e-12 {
                continue;
            }
            if node.children == 0 {
                return false;
            }
            stack[len] = node.children;
            stack[len + 1] = node.children + 1;
            len += 2;
        }
        true
    }

    /// The tree against the primitive `p` (its centers mapped by `x ↦ r·x + t` into `p`'s frame):
    /// [`TreeAnswer::Apart`] when every piece is farther than `threshold` (meters, ≥ 0),
    /// [`TreeAnswer::Touches`] when a node's whole ball lies closer than `padding` to `p` (inside
    /// it for padding 0), so that the pieces it holds — parts of triangles — do too, else
    /// [`TreeAnswer::Unknown`]. The descent takes the deeper child first and gives up the search
    /// for a touching node after [`PROOF_LEAVES`] leaves it could not decide. Empty: `Unknown`.
    pub fn against_primitive(
        &self,
        r: &Matrix3,
        t: &Vector3,
        p: &Primitive,
        threshold: Real,
        padding: Real,
    ) -> TreeAnswer {
        self.against_primitive_to(r, t, p, threshold, padding, |_| false)
    }

    /// [`SphereTree::against_primitive`] with every node `leaf` says is one taken as a leaf: a
    /// descent of a cut ([`SphereTree::cut_by`]) that stops wherever a coarser node already shows
    /// its branch apart.
    pub fn against_primitive_to(
        &self,
        r: &Matrix3,
        t: &Vector3,
        p: &Primitive,
        threshold: Real,
        padding: Real,
        leaf: impl Fn(u32) -> bool,
    ) -> TreeAnswer {
        if self.nodes.is_empty() {
            return TreeAnswer::Unknown;
        }
        // Each entry: a node and its center's signed distance to `p`.
        let sd = |k: u32| primitive_signed_distance(p, &(r * self.nodes[k as usize].sphere.center + t));
        let mut stack = [(0u32, 0.0); MAX_DEPTH + 2];
        stack[0] = (0, sd(0));
        let mut len = 1;
        let mut undecided = 0;
        while len > 0 {
            len -= 1;
            let (k, d) = stack[len];
            let node = &self.nodes[k as usize];
            if d - node.sphere.radius > threshold + 1e-12 {
                continue;
            }
            if d + node.sphere.radius < padding - 1e-12 {
                return TreeAnswer::Touches;
            }
            if node.children == 0 || leaf(k) {
                undecided += 1;
                if undecided > PROOF_LEAVES || padding == Real::NEG_INFINITY {
                    return TreeAnswer::Unknown;
                }
                continue;
            }
            // The deeper child on top of the stack.
            let c = node.children;
            let (da, db) = (sd(c), sd(c + 1));
            let (ra, rb) = (self.nodes[c as usize].sphere.radius, self.nodes[c as usize + 1].sphere.radius);
            let (first, second) = if da - ra <= db - rb { ((c, da), (c + 1, db)) } else { ((c + 1, db), (c, da)) };
            stack[len] = second;
            stack[len + 1] = first;
            len += 2;
        }
        if undecided > 0 {
            TreeAnswer::Unknown
        } else {
            TreeAnswer::Apart
        }
    }

    /// The cut of the tree at radius `stop` (meters): [`SphereTree::cut_by`] with the nodes of
    /// radius at most `stop` small. Each ball holds pieces of the mesh, so every point of a
    /// ball of radius r lies within 2r of the mesh.
    pub fn cut(&self, stop: Real, max_balls: usize) -> Vec<u32> {
        self.cut_by(max_balls, |n| self.nodes[n as usize].sphere.radius <= stop)
    }

    /// A cut of the tree: nodes whose balls together hold every piece, found by splitting the
    /// largest ball that is neither a leaf nor `small` (the root is split at least once when it
    /// has children), at most `max_balls` of them (past that the largest are left unsplit);
    /// node indices, increasing. Empty for an empty tree.
    pub fn cut_by(&self, max_balls: usize, mut small: impl FnMut(u32) -> bool) -> Vec<u32> {
        use std::cmp::Ordering;
        use std::collections::BinaryHeap;
        /// A node ordered by its radius (largest first out of the heap).
        struct ByRadius(Real, u32);
        impl PartialEq for ByRadius {
            fn eq(&self, other: &Self) -> bool {
                self.cmp(other) == Ordering::Equal
            }
        }
        impl Eq for ByRadius {}
        impl PartialOrd for ByRadius {
            fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
                Some(self.cmp(other))
            }
        }
        impl Ord for ByRadius {
            fn cmp(&self, other: &Self) -> Ordering {
                self.0.total_cmp(&other.0).then(other.1.cmp(&self.1))
            }
        }
        if self.nodes.is_empty() {
            return Vec::new();
        }
        let mut done = Vec::new();
        let mut heap = BinaryHeap::from([ByRadius(self.nodes[0].sphere.radius, 0)]);
        while let Some(ByRadius(_, n)) = heap.pop() {
            let children = self.nodes[n as usize].children;
            let first = n == 0;
            if children == 0 || done.len() + heap.len() + 2 > max_balls.max(2) || (!first && small(n)) {
                done.push(n);
                continue;
            }
            for c in [children, children + 1] {
                heap.push(ByRadius(self.nodes[c as usize].sphere.radius, c));
            }
        }
        done.sort_unstable();
        done
    }

    /// A lower bound of the distance from the tree's pieces (centers mapped by `x ↦ r·x + t`
    /// into the primitive `p`'s frame) to `p`: the least `signed distance − radius` over the
    /// cut whose nodes `leaf` names (and the leaves), branches whose bound reaches `cap` or more
    /// dropped (the answer is then at least `cap`); negative where a ball overlaps `p`. `cap`
    /// for an empty tree.
    pub fn lower_bound_to_primitive(
        &self,
        r: &Matrix3,
        t: &Vector3,
        p: &Primitive,
        leaf: impl Fn(u32) -> bool,
        cap: Real,
    ) -> Real {
        if self.nodes.is_empty() {
            return cap;
        }
        let mut best = cap;
        let mut stack = [0u32; MAX_DEPTH + 2];
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let k = stack[len];
            let node = &self.nodes[k as usize];
            let gap = primitive_signed_distance(p, &(r * node.sphere.center + t)) - node.sphere.radius;
            if gap >= best {
                continue;
            }
            if node.children == 0 || leaf(k) {
                best = gap;
                continue;
            }
            stack[len] = node.children;
            stack[len + 1] = node.children + 1;
            len += 2;
        }
        best
    }

    /// Whether every piece of this tree is farther than `threshold` (meters, ≥ 0) from every
    /// piece of `other`, whose centers map into this tree's frame by `x ↦ r·x + t` (a dual
    /// descent, module docs), with a hair for rounding. `false` when either tree is empty.
    pub fn apart_from_tree(&self, other: &SphereTree, r: &Matrix3, t: &Vector3, threshold: Real) -> bool {
        self.apart_from_tree_to(other, r, t, threshold, (|_| false, |_| false))
    }

    /// [`SphereTree::apart_from_tree`] with the nodes `leaves.0` says are leaves of this tree,
    /// and those `leaves.1` says are of `other`, taken as leaves.
    pub fn apart_from_tree_to(
        &self,
        other: &SphereTree,
        r: &Matrix3,
        t: &Vector3,
        threshold: Real,
        leaves: (impl Fn(u32) -> bool, impl Fn(u32) -> bool),
    ) -> bool {
        if self.nodes.is_empty() || other.nodes.is_empty() {
            return false;
        }
        let mut stack = [(0u32, 0u32); 2 * MAX_DEPTH + 2];
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let (i, j) = stack[len];
            let (a, b) = (&self.nodes[i as usize], &other.nodes[j as usize]);
            let reach = a.sphere.radius + b.sphere.radius + threshold + 1e-12;
            if (a.sphere.center - (r * b.sphere.center + t)).norm_squared() > reach * reach {
                continue;
            }
            let ca = if leaves.0(i) { 0 } else { a.children };
            let cb = if leaves.1(j) { 0 } else { b.children };
            match (ca, cb) {
                (0, 0) => return false,
                (ca, cb) if ca != 0 && (cb == 0 || a.sphere.radius >= b.sphere.radius) => {
                    stack[len] = (ca, j);
                    stack[len + 1] = (ca + 1, j);
                }
                (_, cb) => {
                    stack[len] = (i, cb);
                    stack[len + 1] = (i, cb + 1);
                }
            }
            len += 2;
        }
        true
    }
}

/// Cuts every triangle by longest-edge bisection until no edge is longer than `rho`, into
/// `pieces`; `false` (and `pieces` partial) when that takes more than [`MAX_PIECES`].
fn cut(vertices: &[Point3], triangles: &[[u32; 3]], rho: Real, pieces: &mut Vec<Piece>) -> bool {
    pieces.clear();
    let mut work = Vec::new();
    for t in triangles {
        work.push(t.map(|i| vertices[i as usize].coords));
        while let Some(p) = work.pop() {
            let edges = [(p[1] - p[0]).norm(), (p[2] - p[1]).norm(), (p[0] - p[2]).norm()];
            let k = (0..3).max_by(|&a, &b| edges[a].total_cmp(&edges[b])).unwrap_or(0);
            if edges[k] <= rho {
                if pieces.len() == MAX_PIECES {
                    return false;
                }
                pieces.push(p);
                continue;
            }
            // Edge k runs from p[k] to p[k+1]; its midpoint splits the piece in two.
            let (a, b, c) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
            let m = (a + b) / 2.0;
            work.push([a, m, c]);
            work.push([m, b, c]);
        }
    }
    true
}

/// The ball of `pieces`: centered on their vertices' box, radius the largest vertex distance
/// plus the slack (module docs), so that it holds every piece by construction.
fn ball(pieces: &[Piece]) -> Sphere {
    let (mut lo, mut hi) = (pieces[0][0], pieces[0][0]);
    for v in pieces.iter().flatten() {
        lo = lo.inf(v);
        hi = hi.sup(v);
    }
    let c = (lo + hi) * 0.5;
    let r2 = pieces.iter().flatten().map(|v| (v - c).norm_squared()).fold(0.0, Real::max);
    let scale = c.amax() + (hi - lo).amax();
    Sphere { center: c, radius: r2.sqrt() + 1e-9 * (1.0 + scale) }
}

/// The signed distance from the point `x` (the primitive's frame, meters) to the primitive's
/// boundary: positive outside, negative inside (exact; the same value as
/// [`Primitive::closest_boundary_point`], without the point).
pub fn primitive_signed_distance(p: &Primitive, x: &Vector3) -> Real {
    // A box-like set |u_i| ≤ h_i in 2 or 3 coordinates: the outside part and the inside depth.
    fn boxed(q: &[Real]) -> Real {
        let outside: Real = q.iter().map(|v| v.max(0.0).powi(2)).sum::<Real>().sqrt();
        let inside = q.iter().copied().fold(Real::NEG_INFINITY, Real::max).min(0.0);
        outside + inside
    }
    match *p {
        Primitive::Box { half_extents: h } => boxed(&[x.x.abs() - h.x, x.y.abs() - h.y, x.z.abs() - h.z]),
        Primitive::Sphere { radius } => x.norm() - radius,
        Primitive::Cylinder { radius, half_height } => {
            boxed(&[(x.x * x.x + x.y * x.y).sqrt() - radius, x.z.abs() - half_height])
        }
        Primitive::Capsule { radius, half_height } => {
            Vector3::new(x.x, x.y, x.z - x.z.clamp(-half_height, half_height)).norm() - radius
        }
        Primitive::Halfspace { normal, offset } => normal.dot(x) - offset,
    }
}
