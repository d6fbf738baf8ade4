//! Inner balls of closed link meshes: quick proofs that a pair **collides**, the counterpart of
//! the sphere trees' proofs that it is free ([`crate::spheres`]).
//!
//! ```text
//! mesh M, split into its connected components C (vertices welded by position);
//! a component is closed when every directed edge (i, j) of its triangles appears once and
//! (j, i) once: its winding number w_C(x) is then an integer off C, 0 outside C's hull
//! inner ball S = B(c, r) of C:  |w_C(c)| ≥ 1 and r < dist(c, C)   ⇒   w_C ≠ 0 on all of S
//!
//! convex obstacle O (a primitive), padding ≥ 0:
//!     S ∩ O ≠ ∅  and  O reaches outside C's bounding ball   ⇒   a triangle of C meets O
//!     (the segment from a point of S ∩ O to a point of O outside the ball lies in O and
//!      goes from w_C ≠ 0 to w_C = 0, so it crosses C)
//! two components C_A, C_B (a self pair):
//!     S_A ∩ S_B ≠ ∅, C_A reaches outside C_B's bounding ball and C_B outside C_A's
//!         ⇒   a triangle of C_A meets a triangle of C_B
//!     (were they disjoint, the connected C_A would lie where w_B = 0, C_B where w_A = 0, and the
//!      component U of ℝ³ ∖ C_A around a point of S_A ∩ S_B, where w_A ≠ 0, would avoid C_B, so
//!      w_B ≠ 0 on U and on its boundary, which lies in C_A: a contradiction)
//! ```
//!
//! Two more proofs need no closed component:
//!
//! ```text
//! a mesh vertex v closer than the padding to O                    ⇒ the triangles at v are too
//! a vertex (or a sphere-tree node) of a connected mesh A inside an inner ball of C_B, and A
//!     reaching outside C_B's bounding ball                        ⇒ A meets C_B (as above: A
//!     is connected and holds points where w_B ≠ 0 and where w_B = 0)
//! ```
//!
//! A mesh checker (coal, FCL, parry's triangle BVH) calls such a pair in contact, so a proof
//! gives the mesh's own verdict without the mesh. "Reaches outside" is what keeps the proofs
//! exact against those checkers: an obstacle wholly inside a closed link mesh touches no triangle,
//! and is not a contact for them. It is tested on a handful of extreme vertices (a lower bound of
//! the farthest point) for a component, and in closed form for a primitive.
//!
//! **Building** (when a robot is read): the candidates are a grid over each closed component's
//! box; each gets its distance to the component (parry's BVH), and, taken by decreasing distance,
//! a candidate outside every ball already kept gets its winding number (the solid angles of the
//! component's triangles, Van Oosterom and Strackee, 1983); one within 0.25 of a nonzero integer
//! becomes a ball of radius `(1 − 1e-9)·dist − 1e-12`, up to [`MAX_BALLS`] per component. Open
//! components (a soup that does not weld, a mesh with holes) get no balls and prove nothing.

use crate::fitted::LinkShape;
use crate::spheres::{Sphere, SphereTree, TreeAnswer};
use std::collections::HashMap;
use sublevel_core::math::{Isometry3, Matrix3, Point3, Real, Vector3};
use sublevel_core::primitive::Primitive;

/// Most inner balls kept per closed component.
pub const MAX_BALLS: usize = 12;

/// Grid steps per side of a component's box when drawing the candidate centers.
const GRID: usize = 12;

/// One closed component of a link mesh with its inner balls (geometry frame, meters).
#[derive(Clone, Debug, PartialEq)]
pub struct InnerComponent {
    /// Balls inside the component's solid (where its winding number is nonzero), largest first.
    pub balls: Vec<Sphere>,
    /// The component's bounding ball: center of its vertices' box, radius the largest vertex
    /// distance (a hair added).
    pub bound: Sphere,
    /// Its extreme vertices along the 3 axes and the 4 cube diagonals, both ways (≤ 14 points):
    /// the farthest of them from a point is a lower bound of the component's farthest point.
    pub extremes: Vec<Vector3>,
}

/// The inner balls of a link mesh, per closed component (module docs); empty when no component
/// is closed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InnerBalls {
    /// The closed components that hold at least one ball.
    pub components: Vec<InnerComponent>,
    /// Whether the whole mesh is one connected component (closed or not): then any part of
    /// it inside another mesh's closed component, with a vertex outside that component's
    /// bounding ball, proves that the two meet ([`InnerBalls::tree_touches`]).
    pub connected: bool,
    /// The whole mesh's extreme vertices, as [`InnerComponent::extremes`].
    pub extremes: Vec<Vector3>,
    /// A ball tree over the mesh's vertices (welded), one vertex per leaf: a vertex strictly
    /// within the padding of an obstacle proves contact, whatever the mesh's topology.
    pub vertex_tree: SphereTree,
}

impl InnerBalls {
    /// The inner balls of the mesh `vertices` / `triangles` (meters; indices validated by the
    /// caller).
    pub fn build(vertices: &[Point3], triangles: &[[u32; 3]]) -> Self {
        let (welded, tris) = weld(vertices, triangles);
        let all = components(welded.len(), &tris);
        let connected = all.len() == 1;
        let components = all
            .into_iter()
            .filter(|c| closed(c.iter().map(|&k| &tris[k])))
            .filter_map(|c| component(&welded, &c.iter().map(|&k| tris[k]).collect::<Vec<_>>()))
            .collect();
        let points: Vec<Point3> = welded.iter().map(|v| Point3::from(*v)).collect();
        let singles: Vec<[u32; 3]> = (0..points.len() as u32).map(|i| [i, i, i]).collect();
        let vertex_tree = SphereTree::build(&points, &singles, 0.0);
        Self { components, connected, extremes: extremes(&welded), vertex_tree }
    }

    /// Whether the mesh, its points mapped by `x ↦ r·x + t` into the frame of the primitive `p`,
    /// is proved to have a triangle meeting `p` (module docs); `false` proves nothing.
    pub fn touch_primitive(&self, r: &Matrix3, t: &Vector3, p: &Primitive) -> bool {
        self.components.iter().any(|c| {
            let center = r * c.bound.center + t;
            primitive_farthest_distance(p, &center) > c.bound.radius
                && c.balls
                    .iter()
                    .any(|s| crate::spheres::primitive_signed_distance(p, &(r * s.center + t)) < s.radius - ROUNDING)
        })
    }

    /// Whether a vertex of the mesh, mapped by `x ↦ r·x + t` into the frame of the primitive
    /// `p`, lies closer than `padding` (meters, ≥ 0) to `p` (inside it for padding 0): the
    /// triangles at that vertex then come within the padding too.
    pub fn vertex_touches_primitive(&self, r: &Matrix3, t: &Vector3, p: &Primitive, padding: Real) -> bool {
        self.vertex_tree.against_primitive(r, t, p, padding, padding) == TreeAnswer::Touches
    }

    /// Whether this mesh and `other`, whose points map into this mesh's frame by `x ↦ r·x + t`,
    /// are proved to have two triangles that meet (module docs); `false` proves nothing.
    pub fn touch_mesh(&self, other: &InnerBalls, r: &Matrix3, t: &Vector3) -> bool {
        // The other mesh's centers in this frame, and this mesh's in the other's (rᵀ·(x − t)).
        let back = |x: &Vector3| r.tr_mul(&(x - t));
        self.components.iter().any(|a| {
            let a_in_b = back(&a.bound.center);
            other.components.iter().any(|b| {
                let b_center = r * b.bound.center + t;
                let reach = |ext: &[Vector3], c: &Vector3, radius: Real| {
                    ext.iter().any(|v| (v - c).norm_squared() > radius * radius)
                };
                reach(&a.extremes, &b_center, b.bound.radius)
                    && reach(&b.extremes, &a_in_b, a.bound.radius)
                    && a.balls.iter().any(|sa| {
                        b.balls.iter().any(|sb| {
                            let reach = sa.radius + sb.radius - ROUNDING;
                            (sa.center - (r * sb.center + t)).norm_squared() < reach * reach
                        })
                    })
            })
        })
    }

    /// Whether a node of `tree` — the sphere tree of the mesh these balls belong to, in the same
    /// frame — lies wholly inside an inner ball of `other`, whose points map into this frame by
    /// `x ↦ r·x + t`, with this mesh connected and reaching outside that ball's component: the
    /// two meshes then meet (module docs: a connected surface with a point where `w ≠ 0` and one
    /// where `w = 0` crosses the component). The descents stop after a few undecided leaves.
    pub fn tree_touches(&self, tree: &SphereTree, other: &InnerBalls, r: &Matrix3, t: &Vector3) -> bool {
        if !self.connected {
            return false;
        }
        // This mesh's points in the other's frame: rᵀ·(x − t).
        let (rt, tt) = (r.transpose(), -(r.tr_mul(t)));
        other.components.iter().any(|c| {
            let reaches =
                self.extremes.iter().any(|v| (rt * v + tt - c.bound.center).norm_squared() > c.bound.radius.powi(2));
            reaches
                && c.balls.iter().any(|s| {
                    let ball = Primitive::Sphere { radius: s.radius };
                    let t = tt - s.center;
                    self.vertex_tree.against_primitive(&rt, &t, &ball, 0.0, 0.0) == TreeAnswer::Touches
                        || tree.against_primitive(&rt, &t, &ball, 0.0, 0.0) == TreeAnswer::Touches
                })
        })
    }

    /// The number of balls over all components.
    pub fn len(&self) -> usize {
        self.components.iter().map(|c| c.balls.len()).sum()
    }

    /// Whether there is no ball (the mesh proves nothing).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Whether link shape `shape` at `pose` is proved to meet the primitive `p` at `pose_p` (its
/// inner balls, module docs); `false` for a primitive link (its sos answer is exact) or no proof.
pub(crate) fn link_touches_primitive(shape: &LinkShape, pose: &Isometry3, p: &Primitive, pose_p: &Isometry3) -> bool {
    let LinkShape::Mesh { inner, .. } = shape else { return false };
    if inner.is_empty() {
        return false;
    }
    let rel = pose_p.inv_mul(pose);
    inner.touch_primitive(rel.rotation.to_rotation_matrix().matrix(), &rel.translation.vector, p)
}

/// Whether a vertex of link shape `shape` at `pose` lies within `padding` of the primitive `p`
/// at `pose_p` ([`InnerBalls::vertex_touches_primitive`]); `false` for a primitive link.
pub(crate) fn link_vertex_touches(
    shape: &LinkShape,
    pose: &Isometry3,
    p: &Primitive,
    pose_p: &Isometry3,
    padding: Real,
) -> bool {
    let LinkShape::Mesh { inner, .. } = shape else { return false };
    let rel = pose_p.inv_mul(pose);
    inner.vertex_touches_primitive(rel.rotation.to_rotation_matrix().matrix(), &rel.translation.vector, p, padding)
}

/// Whether two link shapes at their poses are proved to meet (module docs): two meshes' inner
/// balls, or a mesh's against a primitive; `false` for two primitives or no proof.
pub(crate) fn links_touch(a: &LinkShape, pa: &Isometry3, b: &LinkShape, pb: &Isometry3) -> bool {
    match (a, b) {
        (LinkShape::Mesh { inner: ia, spheres: ta, .. }, LinkShape::Mesh { inner: ib, spheres: tb, .. }) => {
            let rel = pa.inv_mul(pb);
            let (r, t) = (rel.rotation.to_rotation_matrix().matrix().to_owned(), rel.translation.vector);
            (!ia.is_empty() && !ib.is_empty() && ia.touch_mesh(ib, &r, &t))
                || (!ib.is_empty() && ia.tree_touches(ta, ib, &r, &t))
                || (!ia.is_empty() && ib.tree_touches(tb, ia, &r.transpose(), &-(r.tr_mul(&t))))
        }
        (LinkShape::Mesh { .. }, LinkShape::Primitive(p)) => link_touches_primitive(a, pa, p, pb),
        (LinkShape::Primitive(p), LinkShape::Mesh { .. }) => link_touches_primitive(b, pb, p, pa),
        _ => false,
    }
}

/// Margin of the proofs' strict inequalities (meters), against rounding in the poses.
const ROUNDING: Real = 1e-9;

/// The largest distance from the point `x` (the primitive's frame, meters) to a point of the
/// primitive; +∞ for a halfspace.
pub fn primitive_farthest_distance(p: &Primitive, x: &Vector3) -> Real {
    match *p {
        Primitive::Box { half_extents: h } => (x.abs() + h).norm(),
        Primitive::Sphere { radius } => x.norm() + radius,
        Primitive::Cylinder { radius, half_height } => {
            let rho = (x.x * x.x + x.y * x.y).sqrt() + radius;
            let z = x.z.abs() + half_height;
            (rho * rho + z * z).sqrt()
        }
        Primitive::Capsule { radius, half_height } => (x.abs() + Vector3::new(0.0, 0.0, half_height)).norm() + radius,
        Primitive::Halfspace { .. } => Real::INFINITY,
    }
}

/// The winding number of the triangles `tris` of `vertices` around `x`: the sum of their solid
/// angles seen from `x` over 4π (Van Oosterom and Strackee's formula); an integer off a closed,
/// consistently oriented surface.
pub fn winding_number(vertices: &[Vector3], tris: &[[u32; 3]], x: &Vector3) -> Real {
    let mut total = 0.0;
    for t in tris {
        let [a, b, c] = t.map(|i| vertices[i as usize] - x);
        let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
        let num = a.dot(&b.cross(&c));
        let den = la * lb * lc + a.dot(&b) * lc + a.dot(&c) * lb + b.dot(&c) * la;
        total += 2.0 * num.atan2(den);
    }
    total / (4.0 * std::f64::consts::PI)
}

/// Vertices welded by exact position (the fit crate's welding at tolerance 0: repeated and
/// collapsed triangles dropped, unused vertices too), and the triangles over the welded indices;
/// empty when nothing is left.
fn weld(vertices: &[Point3], triangles: &[[u32; 3]]) -> (Vec<Vector3>, Vec<[u32; 3]>) {
    let mesh = sublevel_fit::mesh::TriangleMesh { vertices: vertices.to_vec(), triangles: triangles.to_vec() };
    match sublevel_fit::mesh::weld_mesh(&mesh, 0.0) {
        Ok(w) => (w.mesh.vertices.iter().map(|p| p.coords).collect(), w.mesh.triangles),
        Err(_) => (Vec::new(), Vec::new()),
    }
}

/// The triangles' connected components (triangles sharing a vertex; triangle indices), by union–find.
fn components(n: usize, tris: &[[u32; 3]]) -> Vec<Vec<usize>> {
    let mut parent: Vec<u32> = (0..n as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for t in tris {
        let r0 = find(&mut parent, t[0]);
        for &v in &t[1..] {
            let r = find(&mut parent, v);
            parent[r as usize] = r0;
        }
    }
    let mut groups: HashMap<u32, Vec<usize>> = HashMap::new();
    for (k, t) in tris.iter().enumerate() {
        groups.entry(find(&mut parent, t[0])).or_default().push(k);
    }
    let mut out: Vec<Vec<usize>> = groups.into_values().collect();
    out.sort_by_key(|c| c[0]);
    out
}

/// Whether the triangles form a closed, consistently oriented surface: no degenerate index
/// triple, every directed edge once and its reverse once.
fn closed<'a>(tris: impl Iterator<Item = &'a [u32; 3]>) -> bool {
    let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
    for t in tris {
        if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
            return false;
        }
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    edges.iter().all(|(&(i, j), &n)| n == 1 && edges.get(&(j, i)) == Some(&1))
}

/// The points' extreme ones along the 3 axes and the 4 cube diagonals, both ways (≤ 14, no
/// repeats).
fn extremes(points: &[Vector3]) -> Vec<Vector3> {
    let dirs = [
        Vector3::x(),
        Vector3::y(),
        Vector3::z(),
        Vector3::new(1.0, 1.0, 1.0),
        Vector3::new(1.0, 1.0, -1.0),
        Vector3::new(1.0, -1.0, 1.0),
        Vector3::new(-1.0, 1.0, 1.0),
    ];
    let mut out: Vec<Vector3> = Vec::new();
    for d in dirs {
        for s in [1.0, -1.0] {
            if let Some(best) = points.iter().max_by(|a, b| (s * d.dot(a)).total_cmp(&(s * d.dot(b)))) {
                if !out.contains(best) {
                    out.push(*best);
                }
            }
        }
    }
    out
}

/// One closed component's inner balls (module docs); `None` when none is found.
fn component(vertices: &[Vector3], tris: &[[u32; 3]]) -> Option<InnerComponent> {
    // The component's own vertices, reindexed, for parry's BVH.
    let mut local: HashMap<u32, u32> = HashMap::new();
    let mut points = Vec::new();
    let local_tris: Vec<[u32; 3]> = tris
        .iter()
        .map(|t| {
            t.map(|i| {
                *local.entry(i).or_insert_with(|| {
                    points.push(vertices[i as usize]);
                    (points.len() - 1) as u32
                })
            })
        })
        .collect();
    let (lo, hi) =
        points.iter().fold((Vector3::repeat(Real::INFINITY), Vector3::repeat(Real::NEG_INFINITY)), |(lo, hi), p| {
            (lo.inf(p), hi.sup(p))
        });
    let center = (lo + hi) * 0.5;
    let radius = points.iter().map(|p| (p - center).norm()).fold(0.0, Real::max);
    let bound = Sphere { center, radius: radius + 1e-9 * (1.0 + center.amax() + radius) };
    let mesh = parry3d_f64::shape::TriMesh::new(
        points.iter().map(|p| parry3d_f64::math::Vector::new(p.x, p.y, p.z)).collect(),
        local_tris.clone(),
    )
    .ok()?;
    let step = (hi - lo) / GRID as Real;
    let mut candidates = Vec::with_capacity(GRID * GRID * GRID);
    for i in 0..GRID {
        for j in 0..GRID {
            for k in 0..GRID {
                let x = lo + step.component_mul(&Vector3::new(i as Real + 0.5, j as Real + 0.5, k as Real + 0.5));
                use parry3d_f64::query::PointQuery;
                let q = mesh.project_local_point(parry3d_f64::math::Vector::new(x.x, x.y, x.z), false).point;
                let d = (x - Vector3::new(q.x, q.y, q.z)).norm();
                candidates.push((d, x));
            }
        }
    }
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0));
    // Balls much smaller than the component prove little and cost a test each.
    let floor = (0.02 * radius).max(1e-4);
    let mut balls: Vec<Sphere> = Vec::new();
    for (d, x) in candidates {
        if balls.len() == MAX_BALLS || d < floor {
            break;
        }
        if balls.iter().any(|s| (x - s.center).norm() < s.radius) {
            continue;
        }
        let w = winding_number(&points, &local_tris, &x);
        if w.round() == 0.0 || (w - w.round()).abs() > 0.25 {
            continue;
        }
        balls.push(Sphere { center: x, radius: (1.0 - 1e-9) * d - 1e-12 });
    }
    if balls.is_empty() {
        return None;
    }
    let extremes = extremes(&points);
    Some(InnerComponent { balls, bound, extremes })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed cube of side 2·h centered at the origin, outward-oriented (12 triangles).
    fn cube(h: Real) -> (Vec<Point3>, Vec<[u32; 3]>) {
        let v = (0..8)
            .map(|k| {
                Point3::new(
                    if k & 1 == 0 { -h } else { h },
                    if k & 2 == 0 { -h } else { h },
                    if k & 4 == 0 { -h } else { h },
                )
            })
            .collect();
        let t = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        (v, t)
    }

    #[test]
    fn a_cube_has_inner_balls_whose_winding_number_is_one() {
        let (v, t) = cube(0.1);
        let inner = InnerBalls::build(&v, &t);
        assert_eq!(inner.components.len(), 1);
        let c = &inner.components[0];
        assert!(!c.balls.is_empty());
        // The largest ball is the grid point nearest the center: within half a cell of it, its
        // radius the distance to the nearest face (closed form).
        let s = c.balls[0];
        assert!(s.center.norm() < 0.1 / GRID as Real * 3f64.sqrt() + 1e-12);
        assert!((s.radius - (0.1 - s.center.amax())).abs() < 1e-9);
        for s in &c.balls {
            assert!(s.center.amax() + s.radius <= 0.1 + 1e-12, "{s:?} leaves the cube");
        }
        let w: Vec<Vector3> = v.iter().map(|p| p.coords).collect();
        assert!((winding_number(&w, &t, &Vector3::zeros()).abs() - 1.0).abs() < 1e-12);
        assert!(winding_number(&w, &t, &Vector3::new(0.3, 0.0, 0.0)).abs() < 1e-12);
    }

    #[test]
    fn a_vertex_within_the_padding_proves_contact() {
        let (v, t) = cube(0.1);
        let inner = InnerBalls::build(&v, &t);
        let id = Matrix3::identity();
        let small = Primitive::Box { half_extents: Vector3::repeat(0.02) };
        // A small box around the corner (0.1, 0.1, 0.1): the corner lies inside it.
        assert!(inner.vertex_touches_primitive(&id, &Vector3::repeat(-0.1), &small, 0.0));
        // The box 0.01 m beyond the corner along x: within a padding of 0.02 m, not of 0.005 m.
        let t = -Vector3::new(0.13, 0.1, 0.1);
        assert!(inner.vertex_touches_primitive(&id, &t, &small, 0.02));
        assert!(!inner.vertex_touches_primitive(&id, &t, &small, 0.005));
        // Touching a face's middle holds no vertex: no proof from the vertices.
        assert!(!inner.vertex_touches_primitive(&id, &-Vector3::new(0.11, 0.0, 0.0), &small, 0.0));
    }

    #[test]
    fn an_open_mesh_proves_nothing() {
        let (v, mut t) = cube(0.1);
        t.pop();
        assert!(InnerBalls::build(&v, &t).is_empty());
    }

    #[test]
    fn a_box_through_the_cube_touches_it_and_one_inside_does_not() {
        let (v, t) = cube(0.1);
        let inner = InnerBalls::build(&v, &t);
        let id = Matrix3::identity();
        // A board crossing the cube's middle: its triangles meet it.
        let board = Primitive::Box { half_extents: Vector3::new(1.0, 1.0, 0.01) };
        assert!(inner.touch_primitive(&id, &Vector3::zeros(), &board));
        // A small box wholly inside the cube meets no triangle: no proof.
        let small = Primitive::Box { half_extents: Vector3::repeat(0.02) };
        assert!(!inner.touch_primitive(&id, &Vector3::zeros(), &small));
        // The board far away: no proof.
        assert!(!inner.touch_primitive(&id, &Vector3::new(0.0, 0.0, 0.5), &board));
        // A halfspace covering half the cube.
        let floor = Primitive::Halfspace { normal: Vector3::z(), offset: 0.0 };
        assert!(inner.touch_primitive(&id, &Vector3::zeros(), &floor));
        // Two cubes overlapping by half; one wholly inside a larger one proves nothing.
        assert!(inner.touch_mesh(&inner, &id, &Vector3::new(0.1, 0.0, 0.0)));
        let (vb, tb) = cube(0.5);
        let big = InnerBalls::build(&vb, &tb);
        assert!(!big.touch_mesh(&inner, &id, &Vector3::zeros()));
        assert!(!inner.touch_mesh(&inner, &id, &Vector3::new(0.25, 0.0, 0.0)));
    }
}
