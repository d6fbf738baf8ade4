//! Tests of the compound fit against closed forms, and of conservativeness on the bundled meshes.

use super::check::uncovered_triangles;
use super::*;
use crate::containment::boundary_points;
use crate::mesh::{parse_off_mesh, TriangleMesh, DEFAULT_MAX_MESH_POINTS};
use sublevel_core::math::{Isometry3, Point3, Real};

/// A closed axis-aligned cube mesh of side `side` centered at `c` (8 vertices, 12 triangles).
fn cube(c: [Real; 3], side: Real, first: u32) -> (Vec<Point3>, Vec<[u32; 3]>) {
    let h = side / 2.0;
    let v = (0..8)
        .map(|k| {
            let s = |b: u32| if (k >> b) & 1 == 0 { -h } else { h };
            Point3::new(c[0] + s(0), c[1] + s(1), c[2] + s(2))
        })
        .collect();
    let faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
    let t = faces.iter().flat_map(|f| [[f[0], f[1], f[2]], [f[0], f[2], f[3]]]).map(|t| t.map(|i| i + first)).collect();
    (v, t)
}

/// Two unit cubes centered at x = ±2: a nonconvex (disconnected) mesh of 24 triangles.
fn two_cubes() -> TriangleMesh {
    let (mut vertices, mut triangles) = cube([-2.0, 0.0, 0.0], 1.0, 0);
    let (v2, t2) = cube([2.0, 0.0, 0.0], 1.0, 8);
    vertices.extend(v2);
    triangles.extend(t2);
    TriangleMesh { vertices, triangles }
}

fn quick_settings(degrees: Vec<usize>) -> CompoundSettings {
    let mut s = CompoundSettings { degrees, resolution: 32, excess_samples: 400, ..CompoundSettings::default() };
    s.fit.volume_samples = 20_000;
    s.containment = s.containment.with_volume_samples(20_000);
    s
}

#[test]
fn two_cubes_give_two_spheres_under_one_root() {
    let mesh = two_cubes();
    let c = fit_compound(&mesh, Some("two_cubes"), PartCount::Fixed(2), &quick_settings(vec![2]), &mut |_| {}).unwrap();
    assert_eq!((c.leaf_count(), c.node_count(), c.height()), (2, 3, 1));
    assert!(uncovered_triangles(&c, &mesh).is_empty());
    let r = c.root();
    for leaf in c.leaves() {
        let n = c.node(leaf);
        // Each part is one whole cube (12 triangles); its degree-2 log det fit is, by the cube's
        // symmetry, the sphere through the 8 corners: radius √3/2 about the cube's center, so the
        // excess over the cube is √3/2 − 1/2 ≈ 0.3660 (at the face centers' directions).
        assert_eq!(n.triangles, 12);
        let center = n.body.interior_point();
        assert!((center.coords.norm() - 2.0).abs() < 1e-4 && center.y.abs() < 1e-4, "center {center}");
        for x in boundary_points(&n.body, &Isometry3::identity(), 50).unwrap() {
            assert!(((x - center).norm() - 3f64.sqrt() / 2.0).abs() < 1e-3, "radius {}", (x - center).norm());
            // The root contains the leaf's body: every boundary point of the leaf is in the root.
            assert!(c.body(r).value_at(&x) <= 1.0 + 1e-9);
        }
        assert!((n.excess - (3f64.sqrt() / 2.0 - 0.5)).abs() < 0.01, "excess {}", n.excess);
        assert_eq!(n.depth, 1);
    }
    // The root reaches beyond the gap between the cubes: at least the leaves' excess, and at the
    // origin (1.5 from both cubes) it contains empty space.
    assert!(c.node(r).excess >= c.max_leaf_excess());
    assert!(c.body(r).value_at(&Point3::origin()) <= 1.0);
    assert_eq!(c.report.attempts.len(), 1);
    assert_eq!(c.report.mesh_triangles, 24);
}

#[test]
fn auto_part_count_stops_at_the_first_count_within_tolerance() {
    let mesh = two_cubes();
    let mut s = quick_settings(vec![2]);
    // One sphere around both cubes reaches ≈ 2.5 − 0.5 beyond them; two spheres 0.366.
    s.excess_tolerance = Some(0.5);
    let c = fit_compound(&mesh, None, PartCount::Auto, &s, &mut |_| {}).unwrap();
    let asked: Vec<usize> = c.report.attempts.iter().map(|a| a.0).collect();
    assert_eq!(asked, vec![1, 2]);
    assert!(c.report.attempts[0].2 > 0.5, "one part: excess {}", c.report.attempts[0].2);
    assert_eq!(c.leaf_count(), 2);
    assert!(c.max_leaf_excess() <= 0.5);
    assert!(uncovered_triangles(&c, &mesh).is_empty());
}

#[test]
fn split_part_separates_the_two_cubes_then_halves_a_cube() {
    let mesh = two_cubes();
    let whole = super::decompose::decompose(&mesh.vertices, &mesh.triangles, 1, 32).unwrap().remove(0);
    let mut halves = super::decompose::split_part(&mesh.vertices, &mesh.triangles, &whole, 32);
    assert_eq!(halves.len(), 2);
    for h in &mut halves {
        h.triangles.sort_unstable();
    }
    halves.sort_by_key(|h| h.triangles[0]);
    assert_eq!(halves[0].triangles, (0..12).collect::<Vec<_>>());
    assert_eq!(halves[1].triangles, (12..24).collect::<Vec<_>>());
    // One cube: whatever the cut, two pieces partition its 12 triangles.
    let pieces = super::decompose::split_part(&mesh.vertices, &mesh.triangles, &halves[0], 32);
    assert!(pieces.len() >= 2);
    let mut all: Vec<usize> = pieces.iter().flat_map(|p| p.triangles.clone()).collect();
    all.sort_unstable();
    assert_eq!(all, (0..12).collect::<Vec<_>>());
}

#[test]
fn auto_refines_parts_above_tolerance_up_to_the_cap() {
    // A 4 × 1 × 1 bar of four unit cubes (48 triangles): convex, so VHACD keeps it nearly whole;
    // refinement cuts it at the median of its triangles until the cap.
    let (mut vertices, mut triangles) = (Vec::new(), Vec::new());
    for k in 0..4u32 {
        let (v, t) = cube([k as Real, 0.0, 0.0], 1.0, 8 * k);
        vertices.extend(v);
        triangles.extend(t);
    }
    let mesh = TriangleMesh { vertices, triangles };
    let mut s = quick_settings(vec![2]);
    // One sphere per cube still reaches 0.366 beyond it: above 0.1, so the cap (4 parts) stops it.
    s.excess_tolerance = Some(0.1);
    s.max_parts = 4;
    let mut reports: Vec<(Real, Option<crate::PartProgress>)> = Vec::new();
    let c = fit_compound(&mesh, None, PartCount::Auto, &s, &mut |p| reports.push((p.fraction, p.part))).unwrap();
    assert_eq!(c.leaf_count(), 4);
    // Progress: the fraction never goes back and ends at 1; every part fit (the attempts' and the
    // refinement's pieces) names its part, 1 ≤ index ≤ count ≤ the cap, up to a count of 4.
    assert!(reports.windows(2).all(|w| w[1].0 >= w[0].0), "fraction went back: {reports:?}");
    assert_eq!(reports.last().map(|r| r.0), Some(1.0));
    let parts: Vec<_> = reports.iter().filter_map(|r| r.1).collect();
    assert!(parts.iter().all(|p| 1 <= p.index && p.index <= p.count && p.count <= 4), "{parts:?}");
    assert!(parts.iter().any(|p| p.count == 4), "{parts:?}");
    assert_eq!(c.report.attempts.last().map(|a| a.1), Some(4));
    assert!(c.max_leaf_excess() < c.report.attempts[0].2, "{:?}", c.report.attempts);
    // Welding merged the corners the cubes share, so the two triangles of each of the 3 shared
    // faces repeat and are dropped once: 42 triangles in the leaves, all 48 covered.
    let total: usize = c.leaves().map(|l| c.node(l).triangles).sum();
    assert_eq!(total, 42);
    let w = c.report.weld.as_ref().unwrap();
    assert_eq!((w.vertices_before, w.vertices_after, w.merged_vertices), (32, 20, 12));
    assert_eq!((w.triangles_before, w.triangles_after, w.duplicate_triangles, w.degenerate_triangles), (48, 42, 6, 0));
    assert_eq!(c.report.mesh_triangles, 48);
    // Still above 0.1 at the cap: a miss per leaf, and a note that the cap stopped refinement.
    assert_eq!(c.report.met, Some(false));
    assert_eq!(c.report.misses.len(), 4);
    assert!(c.report.notes.iter().any(|n| n.contains("--max-parts 4")), "{:?}", c.report.notes);
    assert!(uncovered_triangles(&c, &mesh).is_empty());
    let bad = CompoundSettings { max_parts: 1, ..s };
    assert!(matches!(
        fit_compound(&mesh, None, PartCount::Auto, &bad, &mut |_| {}),
        Err(sublevel_core::Error::InvalidArgument { field, .. }) if field == "max_parts"
    ));
}

#[test]
fn bad_settings_and_meshes_are_refused_by_field() {
    let mesh = two_cubes();
    let fit = |parts: PartCount, s: &CompoundSettings, m: &TriangleMesh| fit_compound(m, None, parts, s, &mut |_| {});
    let field_of = |r: sublevel_core::Result<CompoundBody>| match r {
        Err(sublevel_core::Error::InvalidArgument { field, .. }) => field,
        other => panic!("expected InvalidArgument, got {other:?}"),
    };
    let s = quick_settings(vec![2]);
    assert_eq!(field_of(fit(PartCount::Fixed(0), &s, &mesh)), "parts");
    assert_eq!(field_of(fit(PartCount::Fixed(1000), &s, &mesh)), "parts");
    let t = CompoundSettings { excess_tolerance: Some(-1.0), ..s.clone() };
    assert_eq!(field_of(fit(PartCount::Fixed(2), &t, &mesh)), "tolerance");
    let d = CompoundSettings { degrees: vec![4, 2], ..s.clone() };
    assert_eq!(field_of(fit(PartCount::Fixed(2), &d, &mesh)), "degrees");
    let empty = TriangleMesh { vertices: mesh.vertices.clone(), triangles: vec![] };
    assert_eq!(field_of(fit(PartCount::Fixed(2), &s, &empty)), "mesh");
    let bad = TriangleMesh { vertices: mesh.vertices.clone(), triangles: vec![[0, 1, 99]] };
    assert_eq!(field_of(fit(PartCount::Fixed(2), &s, &bad)), "mesh");
    assert!("auto".parse::<PartCount>().is_ok_and(|p| p == PartCount::Auto));
    assert_eq!(field_of_parse("many"), "parts");
}

fn field_of_parse(s: &str) -> String {
    match s.parse::<PartCount>() {
        Err(sublevel_core::Error::InvalidArgument { field, .. }) => field,
        other => panic!("expected InvalidArgument, got {other:?}"),
    }
}

fn data(path: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(path)
}

fn psb(name: &str) -> TriangleMesh {
    let path = data(&format!("data/psb/{name}.off"));
    parse_off_mesh(&std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())), DEFAULT_MAX_MESH_POINTS)
        .unwrap()
}

/// The bundled PSB meshes; each has a pre-fitted compound file in data/compound/ (see its
/// SOURCE.md for the command).
const PSB: [&str; 5] = ["chair_101", "hand_181", "human_10", "octopus_121", "vase_361"];

#[test]
fn every_bundled_compound_file_covers_every_triangle_of_its_mesh() {
    for name in PSB {
        let mesh = psb(name);
        let c = CompoundBody::load(&data(&format!("data/compound/{name}.json"))).unwrap();
        assert!(c.leaf_count() >= 2, "{name}: {} parts", c.leaf_count());
        assert_eq!(c.report.mesh_triangles, mesh.triangles.len(), "{name}");
        let uncovered = uncovered_triangles(&c, &mesh);
        assert!(uncovered.is_empty(), "{name}: {} of {} triangles uncovered", uncovered.len(), mesh.triangles.len());
        // Each parent contains its children's bodies: their boundary samples have value ≤ 1 in it
        // (the S-procedure certifies all of each child; the samples only spot-check it).
        for i in 0..c.node_count() {
            for &child in c.children(i) {
                for x in boundary_points(c.body(child), &Isometry3::identity(), 200).unwrap() {
                    let v = c.body(i).value_at(&x);
                    assert!(v <= 1.0 + 1e-6, "{name}: node {i} misses a boundary point of child {child} (p = {v})");
                }
            }
        }
        // The excess stored is the one measured against this mesh (recomputed with the same samples).
        let surface = super::surface::MeshSurface::new(&mesh.vertices, &mesh.triangles).unwrap();
        let root = c.root();
        let e = surface.excess(c.body(root), c.report.excess_samples).unwrap();
        assert!((e - c.node(root).excess).abs() < 1e-9, "{name}: root excess {e} vs stored {}", c.node(root).excess);
    }
}

#[test]
fn a_bundled_mesh_fitted_in_two_parts_is_conservative() {
    let mesh = psb("vase_361");
    let c = fit_compound(&mesh, None, PartCount::Fixed(2), &quick_settings(vec![2]), &mut |_| {}).unwrap();
    assert!(uncovered_triangles(&c, &mesh).is_empty());
    let total: usize = c.leaves().map(|l| c.node(l).triangles).sum();
    assert_eq!(total, mesh.triangles.len());
    assert_eq!(c.node(c.root()).triangles, mesh.triangles.len());
}

#[test]
fn the_box_ellipsoid_contains_both_children_and_passes_through_the_box_corners() {
    // Two spheres of radius 1 at x = ±2: the bounding box is [−3, 3] × [−1, 1]², so the box
    // ellipsoid has semi-axes √3 · (3, 1, 1) (closed form) and contains both spheres.
    let a = sublevel_core::body::ellipsoid([-2.0, 0.0, 0.0], [1.0; 3]).unwrap();
    let b = sublevel_core::body::ellipsoid([2.0, 0.0, 0.0], [1.0; 3]).unwrap();
    let id = Isometry3::identity();
    let e = super::tree::box_ellipsoid(&[(&a, id), (&b, id)]).unwrap();
    let s3 = 3.0_f64.sqrt();
    for (x, want) in [([3.0, 1.0, 1.0], 1.0), ([3.0 * s3, 0.0, 0.0], 1.0), ([0.0, s3, 0.0], 1.0), ([0.0; 3], 0.0)] {
        let v = e.value_at(&Point3::from(x));
        assert!((v - want).abs() < 1e-6, "p({x:?}) = {v}, want {want}");
    }
    for child in [&a, &b] {
        for x in boundary_points(child, &id, 200).unwrap() {
            assert!(e.value_at(&x) <= 1.0, "a boundary point {x} of a child is outside");
        }
    }
}

/// `mesh` as a triangle soup: every triangle its own three vertices.
fn soup(mesh: &TriangleMesh) -> TriangleMesh {
    let vertices = mesh.triangles.iter().flat_map(|t| t.map(|i| mesh.vertices[i as usize])).collect();
    let triangles = (0..mesh.triangles.len() as u32).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
    TriangleMesh { vertices, triangles }
}

#[test]
fn a_triangle_soup_is_welded_and_decomposes_like_its_indexed_mesh() {
    let indexed = two_cubes();
    let soup = soup(&indexed);
    assert_eq!(soup.vertices.len(), 72);
    let welded = crate::mesh::weld_mesh(&soup, crate::mesh::DEFAULT_WELD_TOLERANCE).unwrap();
    assert_eq!((welded.mesh.vertices.len(), welded.mesh.triangles.len()), (16, 24));
    // The same parts of the same triangles (welding keeps the triangles' order).
    let parts = |m: &TriangleMesh| -> Vec<Vec<usize>> {
        let mut p: Vec<Vec<usize>> = super::decompose::decompose(&m.vertices, &m.triangles, 2, 32)
            .unwrap()
            .into_iter()
            .map(|mut p| {
                p.triangles.sort_unstable();
                p.triangles
            })
            .collect();
        p.sort();
        p
    };
    assert_eq!(parts(&welded.mesh), parts(&indexed));
    assert_eq!(parts(&indexed), vec![(0..12).collect::<Vec<_>>(), (12..24).collect()]);
    // The compound fits agree: same leaves (triangles, excess), both cover the soup.
    let s = quick_settings(vec![2]);
    let a = fit_compound(&indexed, None, PartCount::Fixed(2), &s, &mut |_| {}).unwrap();
    let b = fit_compound(&soup, None, PartCount::Fixed(2), &s, &mut |_| {}).unwrap();
    let leaves = |c: &CompoundBody| -> Vec<(usize, Real)> {
        let mut l: Vec<(usize, Real)> = c.leaves().map(|i| (c.node(i).triangles, c.node(i).excess)).collect();
        l.sort_by(|x, y| x.1.total_cmp(&y.1));
        l
    };
    let (la, lb) = (leaves(&a), leaves(&b));
    assert_eq!(la.len(), 2);
    for (x, y) in la.iter().zip(&lb) {
        assert_eq!(x.0, y.0);
        assert!((x.1 - y.1).abs() < 1e-6, "excess {} vs {}", x.1, y.1);
    }
    assert!(uncovered_triangles(&b, &soup).is_empty());
    let w = b.report.weld.as_ref().unwrap();
    assert_eq!((w.vertices_before, w.vertices_after, w.merged_vertices), (72, 16, 56));
    assert_eq!(b.report.mesh_triangles, 24);
}

#[test]
fn a_leaf_above_the_tolerance_is_reported_with_its_excess() {
    // A unit cube at x = −2 and a cube of side 0.5 at x = 2: their degree-2 leaves (spheres
    // through the corners) reach (√3 − 1)/2 ≈ 0.366 and half that, 0.183, beyond them. At
    // T = 0.25 the big cube's leaf misses, the small one's meets it.
    let (mut vertices, mut triangles) = cube([-2.0, 0.0, 0.0], 1.0, 0);
    let (v2, t2) = cube([2.0, 0.0, 0.0], 0.5, 8);
    vertices.extend(v2);
    triangles.extend(t2);
    let mesh = TriangleMesh { vertices, triangles };
    let s = CompoundSettings { excess_tolerance: Some(0.25), ..quick_settings(vec![2]) };
    let c = fit_compound(&mesh, None, PartCount::Fixed(2), &s, &mut |_| {}).unwrap();
    assert_eq!(c.report.tolerance, Some(0.25));
    assert_eq!(c.report.met, Some(false));
    assert_eq!(c.report.misses.len(), 1, "{:?}", c.report.misses);
    let miss = &c.report.misses[0];
    let big = c.leaves().find(|&l| c.node(l).body.interior_point().x < 0.0).unwrap();
    assert_eq!(miss.node, big);
    assert_eq!(miss.triangles, 12);
    assert_eq!(miss.excess, c.node(big).excess);
    assert!((miss.excess - (3f64.sqrt() - 1.0) / 2.0).abs() < 0.01, "excess {}", miss.excess);
    // The file keeps the check.
    let json = serde_json::to_string(&c.to_file()).unwrap();
    assert!(json.contains("\"met\":false") && json.contains("\"misses\":[{\"node\":"), "{json}");
    let back = CompoundBody::from_file(serde_json::from_str(&json).unwrap()).unwrap();
    assert_eq!(back.report, c.report);
    // At T = 0.4 both leaves meet it.
    let s = CompoundSettings { excess_tolerance: Some(0.4), ..s };
    let c = fit_compound(&mesh, None, PartCount::Fixed(2), &s, &mut |_| {}).unwrap();
    assert_eq!((c.report.met, c.report.misses.len()), (Some(true), 0));
    // Without a tolerance a fixed part count checks nothing.
    let s = CompoundSettings { excess_tolerance: None, ..s };
    let c = fit_compound(&mesh, None, PartCount::Fixed(2), &s, &mut |_| {}).unwrap();
    assert_eq!((c.report.met, c.report.misses.len()), (None, 0));
}

#[test]
fn auto_without_a_tolerance_takes_one_percent_of_the_diagonal() {
    let mesh = two_cubes();
    let s = CompoundSettings { max_parts: 2, ..quick_settings(vec![2]) };
    let c = fit_compound(&mesh, None, PartCount::Auto, &s, &mut |_| {}).unwrap();
    // The box [−2.5, 2.5] × [−0.5, 0.5]²: diagonal √27.
    let t = c.report.tolerance.unwrap();
    assert!((t - 0.01 * 27f64.sqrt()).abs() < 1e-12, "tolerance {t}");
    // The misses are exactly the leaves above it, largest first.
    let above: Vec<usize> = c.leaves().filter(|&l| c.node(l).excess > t).collect();
    assert_eq!(c.report.met, Some(above.is_empty()));
    let mut missed: Vec<usize> = c.report.misses.iter().map(|m| m.node).collect();
    missed.sort_unstable();
    assert_eq!(missed, above);
    assert!(c.report.misses.windows(2).all(|w| w[0].excess >= w[1].excess));
    assert!(c.report.notes.iter().any(|n| n.contains("bounding-box diagonal")), "{:?}", c.report.notes);
}

/// The UR5 `wrist3.stl` case: VHACD makes a flat cap its own part, and the cap's six vertices
/// (a 7.2 mm hexagon, copied from the mesh) differ by 3.4·10⁻⁸ m across its plane (float32
/// rounding): above the coplanarity test, so the part is fitted as it is. Its degree-2 SDP ended
/// `InsufficientProgress` (log det P stalled near 15.3) and `--parts auto` failed; the fit now
/// thickens the part (to 3·10⁻³ of its size) and solves it in its principal box.
#[test]
fn a_wrist3_like_mesh_with_a_near_flat_part_fits() {
    let (mut vertices, mut triangles) = cube([0.0, 0.062, 0.015], 0.04, 0);
    let cap = [
        [0.001044748, 0.058689475, 0.042999987],
        [0.001984747, 0.065441087, 0.042999975],
        [-0.001793829, 0.065470628, 0.042999979],
        [-0.002593549, 0.059880737, 0.042999953],
        [0.003607971, 0.062014043, 0.042999979],
        [-0.003607963, 0.062635578, 0.042999983],
    ];
    vertices.extend(cap.iter().map(|c| Point3::new(c[0], c[1], c[2])));
    // A fan about vertex 3, counter-clockwise seen from +z: 3, 0, 4, 1, 2, 5.
    triangles.extend([[3, 0, 4], [3, 4, 1], [3, 1, 2], [3, 2, 5]].map(|t: [u32; 3]| t.map(|i| i + 8)));
    let mesh = TriangleMesh { vertices, triangles };
    let s = quick_settings(vec![2, 4, 6]);
    let c = fit_compound(&mesh, Some("wrist3_like"), PartCount::Fixed(2), &s, &mut |_| {}).unwrap();
    assert_eq!(c.leaf_count(), 2);
    assert!(uncovered_triangles(&c, &mesh).is_empty());
    let flat = c.leaves().find(|&l| c.node(l).triangles == 4).expect("the cap is a part of its own");
    let body = &c.node(flat).body;
    assert!(body.report.solver_status.is_usable(), "{:?}", body.report.solver_status);
    assert!(cap.iter().all(|p| body.value_at(&Point3::new(p[0], p[1], p[2])) <= 1.0));
    assert!(body.report.notes.iter().any(|n| n.contains("thickened")), "{:?}", body.report.notes);
    // Thickened by 3·10⁻³ × 7.2 mm: the cap's leaf stays within a millimeter of the cap.
    assert!(c.node(flat).excess < 1e-3, "excess {}", c.node(flat).excess);
    // And `--parts auto` (the command that failed) goes through.
    let c = fit_compound(&mesh, None, PartCount::Auto, &CompoundSettings { max_parts: 4, ..s }, &mut |_| {}).unwrap();
    assert!(uncovered_triangles(&c, &mesh).is_empty());
}
