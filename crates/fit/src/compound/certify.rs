//! Certified containment of a compound body's tree (paper §V): every parent contains each of its
//! children, which the tree queries rely on (a parent's distance bounds its leaves' only when it
//! holds them; a pair whose parents are apart is skipped).
//!
//! Each parent–child edge, children before parents:
//!
//! ```text
//! 1. box:          the 8 corners of the child's bounding box (its tangent planes along the axes,
//!                  a box around the child by convexity) inside the convex parent     → certified
//! 2. S-procedure:  margin γ of 1 − p − γ − τ(1 − g) sos (containment_margin), τ ≥ 0 a
//!                  scalar; γ ≥ −CONTAINMENT_SLACK                                  → certified
//! 3. samples:      a boundary point of the child with p > 1 + VIOLATION_LEVEL      → violated
//! 4. otherwise:    the parent's p divided by the smaller certified factor, times 1 + 10⁻⁹:
//!                  1 − γ (the certificate then has γ = 0), or the largest p at the box's corners
//!                  (p is convex: its largest value on the box is at a corner)  → certified, rescaled
//! ```
//!
//! The S-procedure runs with a scalar multiplier first (3–60 ms for the fitted trees' degree-4 and
//! degree-6 nodes); only an edge it leaves more than 10⁻³ short (a rescale of the parent above
//! that) and the samples do not refute gets a sos quadratic multiplier (2k = 2: a 35 × 35 Gram
//! block for degree-6 bodies, 1.5–3 s; programs with a larger block are not tried), and the
//! better margin sets the rescale.
//!
//! Step 3 samples the child as it was given (before any rescale of its own): a child that grew
//! to contain its children is certified against its parent as it now is (step 4 grows the parent
//! with it), but only the tree as given can prove a parent wrong.
//!
//! A rescaled parent grows by the factor's 2d-th root in size (10⁻⁴ of its size for the
//! γ ≈ −4·10⁻⁴ that some fitted parents show: their fit checks containment on samples), and is
//! checked against its own parent after that.

use super::CompoundNode;
use crate::containment::{boundary_points, containment_margin, CONTAINMENT_SLACK};
use crate::{Error, Result};
use sublevel_core::body::Body;
use sublevel_core::math::{Isometry3, Point3, Real, Vector3};

/// Slack on p ≤ 1 at the box corners (dimensionless): the rounding of a file round trip.
pub const BOX_TOLERANCE: Real = 1e-9;

/// Value of the parent's p above which a boundary point of the child proves that the parent does
/// not contain it (dimensionless; a shortfall below it is repaired by rescaling the parent).
pub const VIOLATION_LEVEL: Real = 1e-3;

/// Boundary points of a child sampled in step 3.
const VIOLATION_SAMPLES: usize = 512;

/// How one parent–child containment was certified.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ContainmentProof {
    /// The corners of the child's bounding box lie in the parent.
    BoxCorners,
    /// An S-procedure certificate with margin `margin` ≥ −[`CONTAINMENT_SLACK`] and a multiplier
    /// of degree `multiplier_degree`.
    SProcedure {
        /// The certified margin γ (1 − p ≥ γ on the child).
        margin: Real,
        /// Degree 2k of the multiplier τ.
        multiplier_degree: usize,
    },
    /// The parent's p was divided by `factor` > 1, after which the S-procedure certificate of
    /// margin `margin` < −[`CONTAINMENT_SLACK`] (found before) has margin 0.
    Rescaled {
        /// The divisor of the parent's polynomial.
        factor: Real,
        /// The margin before the rescale.
        margin: Real,
    },
}

/// The certificate of one edge of the tree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeCertificate {
    /// Index of the parent node.
    pub parent: usize,
    /// Index of the child node.
    pub child: usize,
    /// How the containment was certified.
    pub proof: ContainmentProof,
}

/// Certifies that every parent of the tree `nodes` contains its children, children first, and
/// rescales a parent whose certificate falls short by less than a proven violation (see the
/// module docs); a rescaled parent's report gets `containment_rescale` multiplied by the factor
/// and a note. Returns one certificate per edge.
///
/// Every node must be convex (sos-convex certified): the box step relies on it.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `nodes[i]` when node i provably does not contain its child
/// (a boundary point of the child where p > 1 + [`VIOLATION_LEVEL`], given in the message), or
/// when a node is nonconvex or names a child out of range; [`Error::Numerical`] when a body cannot
/// be rebuilt after a rescale.
pub fn certify_tree(nodes: &mut [CompoundNode]) -> Result<Vec<EdgeCertificate>> {
    let n = nodes.len();
    for (i, node) in nodes.iter().enumerate() {
        if node.body.report.nonconvex {
            return Err(Error::invalid(format!("nodes[{i}]"), "is not convex: a tree's nodes must be"));
        }
        if let Some(&c) = node.children.iter().find(|&&c| c >= n) {
            return Err(Error::invalid(format!("nodes[{i}].children"), format!("child {c} is out of range")));
        }
    }
    // Children before parents: one level at a time, deepest first. (The edges of a level could
    // run in parallel, but Clarabel's PSD cones call a threaded OpenBLAS: two solves at once
    // took 1.7× longer than one after the other on 2 cores.)
    let max_depth = nodes.iter().map(|n| n.depth).max().unwrap_or(0);
    let mut out = Vec::new();
    // The bodies as given of the nodes rescaled so far (step 3 samples those).
    let mut given: std::collections::HashMap<usize, Body> = std::collections::HashMap::new();
    for depth in (0..=max_depth).rev() {
        let edges: Vec<(usize, usize)> = (0..n)
            .filter(|&i| nodes[i].depth == depth)
            .flat_map(|i| nodes[i].children.iter().map(move |&c| (i, c)))
            .collect();
        let checks: Vec<Result<Edge>> = edges
            .iter()
            .map(|&(i, c)| check_edge(&nodes[i].body, &nodes[c].body, given.get(&c).unwrap_or(&nodes[c].body)))
            .collect();
        // Per parent: the largest rescale its children need.
        let mut needs: std::collections::BTreeMap<usize, (Real, Real, Vec<usize>)> = Default::default();
        for (&(i, c), check) in edges.iter().zip(checks) {
            match check? {
                Edge::Certified(proof) => out.push(EdgeCertificate { parent: i, child: c, proof }),
                Edge::Short { factor, margin } => {
                    let e = needs.entry(i).or_insert((1.0, Real::INFINITY, Vec::new()));
                    e.0 = e.0.max(factor * (1.0 + 1e-9));
                    e.1 = e.1.min(margin);
                    e.2.push(c);
                }
                Edge::Violated(point, value) => {
                    return Err(Error::invalid(
                        format!("nodes[{i}]"),
                        format!(
                            "does not contain its child nodes[{c}]: the child's point ({:.6}, {:.6}, {:.6}) m has p = {value:.6} > 1 in node {i}",
                            point.x, point.y, point.z
                        ),
                    ));
                }
            }
        }
        for (i, (factor, margin, children)) in needs {
            let body = rescaled(&nodes[i].body, factor, margin)?;
            given.insert(i, std::mem::replace(&mut nodes[i].body, body));
            out.extend(children.into_iter().map(|c| EdgeCertificate {
                parent: i,
                child: c,
                proof: ContainmentProof::Rescaled { factor, margin },
            }));
        }
    }
    Ok(out)
}

/// What one edge's check found.
enum Edge {
    Certified(ContainmentProof),
    /// Not certified, not violated: the smallest certified divisor of the parent's p (> 1) and
    /// the best S-procedure margin (< −slack; −∞ when no solve succeeded).
    Short {
        factor: Real,
        margin: Real,
    },
    /// A boundary point of the child and the parent's p there (> 1 + [`VIOLATION_LEVEL`]).
    Violated(Point3, Real),
}

/// Steps 1–4 of the module docs for one edge: `child` as it is now, `child_given` as the tree
/// gave it (the same body unless it was rescaled).
fn check_edge(parent: &Body, child: &Body, child_given: &Body) -> Result<Edge> {
    let id = Isometry3::identity();
    let (lo, hi) = child
        .world_aabb(&id)
        .ok_or_else(|| Error::invalid("nodes", "a tree's nodes must be convex (no bounding box)"))?;
    let corner_max = (0..8)
        .map(|corner| {
            let x = Vector3::from_fn(|k, _| if (corner >> k) & 1 == 0 { lo[k] } else { hi[k] });
            parent.value_at(&Point3::from(x))
        })
        .fold(Real::NEG_INFINITY, |a, b| if b > a || b.is_nan() { b } else { a });
    if corner_max <= 1.0 + BOX_TOLERANCE {
        return Ok(Edge::Certified(ContainmentProof::BoxCorners));
    }
    let best = match s_procedure(parent, child, 0)? {
        Ok(proof) => return Ok(Edge::Certified(proof)),
        Err(gamma) => gamma,
    };
    let points = boundary_points(child_given, &id, VIOLATION_SAMPLES)?;
    let worst = points.iter().map(|x| (*x, parent.value_at(x))).fold((Point3::origin(), Real::NEG_INFINITY), |a, b| {
        if b.1 > a.1 || b.1.is_nan() {
            b
        } else {
            a
        }
    });
    if worst.1 > 1.0 + VIOLATION_LEVEL || worst.1.is_nan() {
        return Ok(Edge::Violated(worst.0, worst.1));
    }
    // A scalar multiplier far short: a sos quadratic one may certify (bounded: at most a 35 × 35
    // Gram block).
    let best = if best < -VIOLATION_LEVEL && child.degree().max(parent.degree().saturating_sub(2)) + 2 <= 8 {
        match s_procedure(parent, child, 2)? {
            Ok(proof) => return Ok(Edge::Certified(proof)),
            Err(gamma) => best.max(gamma),
        }
    } else {
        best
    };
    // Both factors are certified (the box's by convexity); a loose relaxation may make 1 − γ the
    // larger one.
    let factor = if best.is_finite() { (1.0 - best).min(corner_max) } else { corner_max };
    if !factor.is_finite() {
        return Err(Error::Numerical(format!("no certified rescale of the parent (corner value {corner_max})")));
    }
    Ok(Edge::Short { factor, margin: best })
}

/// The S-procedure step with a multiplier of degree `multiplier_degree`: the proof when the
/// margin γ ≥ −[`CONTAINMENT_SLACK`], else γ (−∞ when the solve found no certificate: infeasible
/// or failed).
fn s_procedure(
    parent: &Body,
    child: &Body,
    multiplier_degree: usize,
) -> Result<std::result::Result<ContainmentProof, Real>> {
    match containment_margin(parent, child, multiplier_degree) {
        Ok(margin) if margin >= -CONTAINMENT_SLACK => {
            Ok(Ok(ContainmentProof::SProcedure { margin, multiplier_degree }))
        }
        Ok(margin) => Ok(Err(margin)),
        Err(Error::Numerical(_)) => Ok(Err(Real::NEG_INFINITY)),
        Err(e) => Err(e),
    }
}

/// `body` with its polynomial divided by `factor` (> 1: a larger body), its report noting it.
fn rescaled(body: &Body, factor: Real, margin: Real) -> Result<Body> {
    let mut file = body.to_file();
    for c in &mut file.coefficients {
        *c /= factor;
    }
    file.report.containment_rescale *= factor;
    file.report.notes.push(format!(
        "rescaled by {factor:.9} to contain its children (their best S-procedure margin was {margin:.3e})"
    ));
    Body::from_file(file)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_core::body::ellipsoid;
    use sublevel_core::compound::CompoundBody;

    /// A sphere of radius `r` at `c` as a tree node.
    fn node(c: [Real; 3], r: Real, children: Vec<usize>, depth: usize) -> CompoundNode {
        CompoundNode {
            body: ellipsoid(c, [r; 3]).unwrap(),
            children,
            depth,
            excess: Real::NAN,
            triangles: 0,
            fit_seconds: 0.0,
        }
    }

    #[test]
    fn a_parent_that_does_not_hold_its_children_is_refused_with_a_point() {
        // The hostile tree: a 0.1 m root over 1 m spheres 5 m away.
        let mut nodes = vec![
            node([0.0; 3], 0.1, vec![1, 2], 0),
            node([-5.0, 0.0, 0.0], 1.0, vec![], 1),
            node([5.0, 0.0, 0.0], 1.0, vec![], 1),
        ];
        let e = certify_tree(&mut nodes).unwrap_err();
        assert!(matches!(&e, Error::InvalidArgument { field, .. } if field == "nodes[0]"), "{e}");
        // A root of radius 2.5 covering them partly.
        nodes[0] = node([0.0; 3], 2.5, vec![1, 2], 0);
        assert!(certify_tree(&mut nodes).is_err());
        // A root that holds both: certified, unchanged.
        nodes[0] = node([0.0; 3], 6.0, vec![1, 2], 0);
        let before = nodes[0].body.polynomial().coefficients().to_vec();
        let certs = certify_tree(&mut nodes).unwrap();
        assert_eq!(certs.len(), 2);
        assert_eq!(nodes[0].body.polynomial().coefficients(), &before[..]);
    }

    #[test]
    fn a_parent_short_by_little_is_rescaled_to_a_certificate() {
        // A parent of radius 0.9999 around a unit sphere: p = 1/0.9999² ≈ 1.0002 on the child
        // (below the violation level), so the parent is rescaled to contain it.
        let mut nodes = vec![node([0.0; 3], 0.9999, vec![1], 0), node([0.0; 3], 1.0, vec![], 1)];
        let certs = certify_tree(&mut nodes).unwrap();
        let ContainmentProof::Rescaled { factor, .. } = certs[0].proof else { panic!("{:?}", certs[0]) };
        let exact = 1.0 / (0.9999 * 0.9999);
        assert!(factor >= exact && factor < exact * (1.0 + 1e-6), "factor {factor}, needed {exact}");
        // The rescaled parent holds the child's boundary (p ≤ 1 on it), and now certifies.
        for x in boundary_points(&nodes[1].body, &Isometry3::identity(), 200).unwrap() {
            assert!(nodes[0].body.value_at(&x) <= 1.0 + 1e-12);
        }
        assert!(containment_margin(&nodes[0].body, &nodes[1].body, 0).unwrap() >= -CONTAINMENT_SLACK);
        assert!(nodes[0].body.report.notes.iter().any(|n| n.contains("rescaled")));
    }

    #[test]
    fn the_bundled_compound_bodies_certify_with_parents_grown_by_under_a_thousandth() {
        // The fitted trees: box-ellipsoid parents certify by their box, containment fits by the
        // S-procedure or a rescale (their fit checks containment on samples only).
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/compound");
        for name in ["human_10", "vase_361"] {
            let tree = CompoundBody::load(&dir.join(format!("{name}.json"))).unwrap();
            let mut nodes = tree.nodes().to_vec();
            let certs = certify_tree(&mut nodes).unwrap();
            assert_eq!(certs.len(), tree.node_count() - 1, "{name}: one certificate per edge");
            for c in &certs {
                if let ContainmentProof::Rescaled { factor, .. } = c.proof {
                    // The parent grows by factor^(1/2d) in size: by less than 0.1 %.
                    let growth = factor.powf(1.0 / tree.body(c.parent).degree() as Real) - 1.0;
                    assert!(growth < 1e-3, "{name}: {c:?}, size growth {growth:e}");
                }
            }
        }
    }
}
