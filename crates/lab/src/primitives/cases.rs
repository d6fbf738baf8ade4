//! The reference cases of `scripts/peers/coal_primitives.py`: per row a pair type, both poses,
//! coal 3.0.3's signed distance, witness points and collision verdict; and the shapes each pair
//! type names.

use std::path::Path;
use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};
use sublevel_core::primitive::{Primitive, PrimitiveFile};
use sublevel_core::{Error, Result};

/// One reference case.
#[derive(Clone, Debug)]
pub struct Case {
    /// Pair type, `A-B` (e.g. `box-cylinder`; a halfspace is always A).
    pub pair: String,
    /// Pose of A.
    pub pose_a: Isometry3,
    /// Pose of B.
    pub pose_b: Isometry3,
    /// coal's signed distance (meters; minus the penetration depth when overlapping).
    pub distance: Real,
    /// coal's collision verdict.
    pub overlapping: bool,
}

/// Reads the cases CSV (header row, then `pair`, 7 + 7 pose numbers, distance, 6 witness
/// coordinates, overlapping 0/1).
///
/// # Errors
/// [`Error::Io`], or [`Error::InvalidArgument`] naming the line of a malformed row.
pub fn load_cases(path: &Path) -> Result<Vec<Case>> {
    let text = std::fs::read_to_string(path)?;
    text.lines()
        .skip(1)
        .enumerate()
        .map(|(i, line)| {
            parse_row(line)
                .ok_or_else(|| Error::invalid(format!("{}:{}", path.display(), i + 2), "expected pair and 22 numbers"))
        })
        .collect()
}

fn parse_row(line: &str) -> Option<Case> {
    let mut fields = line.split(',');
    let pair = fields.next()?.to_string();
    let v: Vec<Real> = fields.map(|s| s.parse().ok()).collect::<Option<_>>()?;
    if v.len() != 22 {
        return None;
    }
    let pose = |o: usize| {
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(v[o], v[o + 1], v[o + 2], v[o + 3]));
        Isometry3::from_parts(Vector3::new(v[o + 4], v[o + 5], v[o + 6]).into(), q)
    };
    Some(Case { pair, pose_a: pose(0), pose_b: pose(7), distance: v[14], overlapping: v[21] == 1.0 })
}

/// The shapes (A, B) of a pair type, as `scripts/peers/coal_primitives.py` defines them.
///
/// # Errors
/// [`Error::InvalidArgument`] for a pair type the script does not write.
pub fn pair_shapes(pair: &str) -> Result<(Primitive, Primitive)> {
    let block = PrimitiveFile::Box { size: [0.4, 0.3, 0.2] };
    let board = PrimitiveFile::Box { size: [1.2, 1.0, 0.04] };
    let rod = PrimitiveFile::Cylinder { radius: 0.05, height: 0.3 };
    let can = PrimitiveFile::Cylinder { radius: 0.1, height: 0.2 };
    let ball = PrimitiveFile::Sphere { radius: 0.1 };
    let big_ball = PrimitiveFile::Sphere { radius: 0.25 };
    let capsule = PrimitiveFile::Capsule { radius: 0.05, height: 0.3 };
    let short_capsule = PrimitiveFile::Capsule { radius: 0.08, height: 0.2 };
    let floor = PrimitiveFile::Halfspace { normal: [0.0, 0.0, 1.0], offset: 0.0 };
    let (a, b) = match pair {
        "box-box" => (block, board),
        "box-cylinder" => (block, rod),
        "cylinder-cylinder" => (rod, can),
        "sphere-sphere" => (ball, big_ball),
        "sphere-box" => (ball, block),
        "sphere-cylinder" => (ball, rod),
        "capsule-capsule" => (capsule, short_capsule),
        "capsule-box" => (capsule, block),
        "capsule-cylinder" => (capsule, can),
        "halfspace-box" => (floor, block),
        "halfspace-cylinder" => (floor, rod),
        "halfspace-capsule" => (floor, capsule),
        "halfspace-sphere" => (floor, ball),
        other => return Err(Error::invalid("pair", format!("unknown pair type {other}"))),
    };
    Ok((Primitive::from_file(&a)?, Primitive::from_file(&b)?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_core::math::Point3;
    use sublevel_query::shape::{shape_distance, ShapeRef};
    use sublevel_query::SolveStatus;

    fn surface_gap(p: &Primitive, pose: &Isometry3, x: &Point3) -> Real {
        p.closest_boundary_point(&pose.inverse_transform_point(x).coords).0
    }

    /// Against coal 3.0.3 (GJK at tolerance 10⁻¹², closed forms; `scripts/peers/coal_primitives.py`),
    /// 150 random poses for each of 13 pair types: overlap flags agree; separated distances agree
    /// within 10⁻⁸ m and our witnesses lie on both surfaces within 10⁻⁸ m (coal's own answers are
    /// within 10⁻¹⁰ of the independent reference its script checks them against).
    #[test]
    fn primitive_distances_agree_with_coal() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../query/tests/data/coal_primitives.csv");
        let cases = load_cases(&path).unwrap();
        assert_eq!(cases.len(), 13 * 150);
        for c in &cases {
            let (a, b) = pair_shapes(&c.pair).unwrap();
            let r =
                shape_distance(ShapeRef::Primitive(&a), &c.pose_a, ShapeRef::Primitive(&b), &c.pose_b, None).unwrap();
            assert_eq!(r.status, SolveStatus::Converged, "{}", c.pair);
            assert_eq!(r.overlapping, c.overlapping, "{}: ours {r:?}, coal {}", c.pair, c.distance);
            if c.overlapping {
                continue;
            }
            let err = (r.distance - c.distance).abs();
            let off =
                surface_gap(&a, &c.pose_a, &r.witness_a).abs().max(surface_gap(&b, &c.pose_b, &r.witness_b).abs());
            assert!(err <= 1e-8, "{}: ours {} coal {}", c.pair, r.distance, c.distance);
            assert!(off <= 1e-8, "{}: witness {off:e} m off the surface", c.pair);
        }
    }

    /// The signed distance inside contact against coal's EPA depths on the overlapping cases
    /// (which its script checked against a direction search within 10⁻⁹ m).
    #[test]
    fn penetration_depths_agree_with_coal() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../query/tests/data/coal_primitives.csv");
        let cases = load_cases(&path).unwrap();
        let mut worst: std::collections::BTreeMap<String, (Real, usize, Real, usize)> = Default::default();
        for c in cases.iter().filter(|c| c.overlapping) {
            let (a, b) = pair_shapes(&c.pair).unwrap();
            let s = sublevel_query::shape::shape_signed_distance(
                ShapeRef::Primitive(&a),
                &c.pose_a,
                ShapeRef::Primitive(&b),
                &c.pose_b,
                None,
            )
            .unwrap();
            let e = worst.entry(c.pair.clone()).or_default();
            // Never shallower than the true depth; exact when converged.
            assert!(s.value <= c.distance + 1e-9, "{}: ours {} coal {}", c.pair, s.value, c.distance);
            if s.converged {
                assert!((s.value - c.distance).abs() <= 1e-8, "{}: ours {} coal {}", c.pair, s.value, c.distance);
                e.0 = e.0.max((s.value - c.distance).abs());
            } else {
                e.1 += 1;
                e.2 = e.2.max((s.value - c.distance).abs());
            }
            e.3 += 1;
        }
        for (p, e) in &worst {
            eprintln!("{p:>20}: converged worst {:.1e} m; flagged {}/{} (worst {:.1e} m, deeper)", e.0, e.1, e.3, e.2);
        }
    }
}

#[cfg(test)]
mod compound_tests {
    use std::path::Path;
    use sublevel_core::compound::CompoundBody;
    use sublevel_core::math::{Isometry3, Real, UnitQuaternion, Vector3};
    use sublevel_core::primitive::{Primitive, PrimitiveFile};
    use sublevel_query::dispatch::{primitive_pair_distance, PosedRef};
    use sublevel_scene::bounding_body;

    /// The bundled compound chair (64 leaves fitted to `data/psb/chair_101.off`) against 200 boxes
    /// around it, beside coal 3.0.3's exact mesh–box distances (`scripts/peers/coal_mesh_boxes.py`):
    /// never farther than the mesh (the leaves contain it: the conservative side), and within the
    /// compound's largest leaf excess (38.7 mm) of it on at least 195 of the 200 (measured: 197; the
    /// median gap is 2.3 mm). The stated excess is sampled against each leaf's convex part, which
    /// fills the mesh's concavities, so it is not a bound against the mesh itself: the worst box is
    /// 76.6 mm nearer to the compound than to the mesh.
    #[test]
    fn a_compound_body_against_boxes_is_conservative_and_near_the_mesh() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let tree = CompoundBody::load(&root.join("data/compound/chair_101.json")).unwrap();
        let excess = tree.max_leaf_excess();
        let text = std::fs::read_to_string(root.join("crates/lab/tests/data/coal_chair_boxes.csv")).unwrap();
        let mut worst_gap: Real = 0.0;
        let mut gaps = Vec::new();
        let mut cases = 0;
        for line in text.lines().skip(1) {
            let v: Vec<Real> = line.split(',').map(|s| s.parse().unwrap()).collect();
            let cube = Primitive::from_file(&PrimitiveFile::Box { size: [v[0], v[1], v[2]] }).unwrap();
            let stand_in = bounding_body(&cube).unwrap().unwrap();
            let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(v[3], v[4], v[5], v[6]));
            let pose = Isometry3::from_parts(Vector3::new(v[7], v[8], v[9]).into(), q);
            let mesh = v[10].max(0.0);
            let a = PosedRef {
                body: tree.body(tree.root()),
                tree: Some(&tree),
                primitive: None,
                pose: Isometry3::identity(),
            };
            let b = PosedRef { body: &stand_in, tree: None, primitive: Some(&cube), pose };
            let r = primitive_pair_distance(&a, &b, None).unwrap();
            assert!(r.converged(), "{r:?}");
            let d = r.distance.distance;
            assert!(d <= mesh + 1e-9, "compound {d} farther than the mesh {mesh}");
            gaps.push(mesh - d);
            worst_gap = worst_gap.max(mesh - d);
            cases += 1;
        }
        assert_eq!(cases, 200);
        gaps.sort_by(Real::total_cmp);
        let within = gaps.iter().filter(|g| **g <= excess).count();
        eprintln!(
            "compound chair against boxes: mesh − compound median {:.4} m, worst {worst_gap:.4} m; {within} of 200 within the excess {excess:.4} m",
            gaps[gaps.len() / 2]
        );
        assert!(within >= 195, "{within} of 200 within the stated excess");
        assert!(gaps[gaps.len() / 2] <= 0.1 * excess);
    }
}
