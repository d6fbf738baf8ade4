//! Integration tests: Table 1 baselines, the independent MVEE, `--degree auto`, and the
//! `sublevel-lab table1` command on the paper's meshes.

use sublevel_core::math::{Point3, Real};
use sublevel_fit::auto::fit_auto;
use sublevel_fit::baselines::{baselines, convex_hull, mvee_khachiyan};
use sublevel_fit::{fit_points, mesh, FitSettings};

fn psb_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join("data/psb")
}

/// The 2d = 2 log det P fit of the chair is its minimum-volume enclosing ellipsoid: Khachiyan's
/// algorithm on the hull vertices (certified to a relative duality gap of 1e-7) gives the same
/// volume within the fit's Monte Carlo error, and the paper's 1.79 is below the certified lower
/// bound.
#[test]
fn khachiyan_mvee_of_the_chair_matches_the_2d2_logdet_fit() {
    let pts = mesh::load_points(&psb_dir().join("chair_101.off")).unwrap();
    let hull = convex_hull(&pts).unwrap();
    let e = mvee_khachiyan(&hull.vertices, 1e-7, 200_000).unwrap();
    assert!(e.relative_gap() <= 1e-7, "gap {}", e.relative_gap());
    assert!(pts.iter().all(|p| e.ellipsoid.contains(p)));
    let body = fit_points(&pts, &FitSettings::default().with_degree(2), &mut |_| {}).unwrap();
    let (v, se) = (body.report.volume, body.report.volume_std_error);
    assert!((v - e.volume).abs() <= 3.0 * se, "fit {v} ± {se} vs MVEE {}", e.volume);
    assert!((e.volume - 1.8425).abs() < 1e-3, "{}", e.volume);
    assert!(e.lower_bound > 1.79 + 0.005);
}

/// `--degree auto` on an ellipsoid cloud keeps 2d = 2: the degree-4 body is not smaller.
#[test]
fn auto_degree_keeps_2_on_an_ellipsoid_cloud() {
    let (a, b, c) = (1.0, 0.6, 0.4);
    let n = 500;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let pts: Vec<Point3> = (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as Real + 0.5) / n as Real;
            let rho = (1.0 - z * z).sqrt();
            let th = golden * i as Real;
            Point3::new(2.0 + a * rho * th.cos(), b * rho * th.sin(), -1.0 + c * z)
        })
        .collect();
    let settings = FitSettings::default().with_volume_samples(100_000);
    let mut messages = Vec::new();
    let body = fit_auto(&pts, &settings, &[2, 4, 6], 0.05, &mut |p| messages.push(p.message.clone())).unwrap();
    assert_eq!(body.degree(), 2);
    let choice = body.report.degree_choice.clone().unwrap();
    assert_eq!(choice.chosen, 2, "{}", choice.reason);
    // Stops as soon as the choice is made: 6 is never fitted.
    assert_eq!(choice.candidates.iter().map(|c| c.0).collect::<Vec<_>>(), vec![2, 4], "{}", choice.reason);
    let (v2, v4) = (choice.candidates[0].1, choice.candidates[1].1);
    assert!(v2 <= 1.05 * v4, "{v2} vs {v4}");
    let exact = 4.0 / 3.0 * std::f64::consts::PI * a * b * c;
    assert!((v2 - exact).abs() <= 3.0 * choice.candidates[0].2 + 1e-3 * exact, "{v2} vs {exact}");
    assert!(
        choice.reason.starts_with("degree 2 was kept because degree 4 shrinks the volume only"),
        "{}",
        choice.reason
    );
    assert!(body.report.notes.iter().any(|n| n.contains(&choice.reason)));
    assert!(
        messages.iter().any(|m| m.starts_with("degree 2: ")) && messages.iter().any(|m| m.starts_with("degree 4: "))
    );
    assert!(!messages.iter().any(|m| m.starts_with("degree 6: ")));
}

/// Axis-aligned boxes in file coordinates of the five meshes, from SOURCE.md (scipy).
const SOURCE_AABB: [(&str, Real); 5] =
    [("human_10", 0.697), ("chair_101", 1.009), ("hand_181", 1.222), ("vase_361", 2.048), ("octopus_121", 1.645)];

/// `sublevel-lab table1 --rows hull,sphere,obb,aabb`: hull, minimum ball and minimum-volume box match
/// the paper's Table 1 to 2 decimals (|ours − paper| < 0.01, e.g. 0.66, 1.0 for the chair; the
/// ball within 0.015),
/// the axis-aligned box matches SOURCE.md's; the CSV has one line per (row, shape).
#[test]
fn table1_baselines_match_the_paper() {
    let dir = tempfile::tempdir().unwrap();
    let csv_path = dir.path().join("t1.csv");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_sublevel-lab"))
        .arg("table1")
        .arg(psb_dir())
        .args(["--rows", "hull,sphere,obb,aabb", "--csv"])
        .arg(&csv_path)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("Chair (101)") && stdout.contains("8499/320"), "{stdout}");
    let text = std::fs::read_to_string(&csv_path).unwrap();
    let mut reader = csv::Reader::from_path(&csv_path).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(&header[..9], ["row", "objective", "degree", "c", "shape", "volume", "std_error", "paper", "ratio"]);
    let records: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    let lines: Vec<Vec<&str>> = records.iter().map(|r| r.iter().collect()).collect();
    assert_eq!(lines.len(), 4 * 5);
    for l in &lines {
        let (row, shape, volume) = (l[0], l[4], l[5].parse::<Real>().unwrap());
        if row == "aabb" {
            let reference = SOURCE_AABB.iter().find(|s| s.0 == shape).unwrap().1;
            assert!((volume - reference).abs() < 1e-3, "aabb {shape}: {volume} vs {reference}");
        } else {
            let paper = l[7].parse::<Real>().unwrap();
            // The minimum ball is exact (Welzl, tested against brute force); the paper's sphere
            // values for the human and the chair look swapped (ours 3.730 / 3.742, paper 3.74 /
            // 3.73), so the ball gets 0.015.
            let tol = if row == "sphere" { 0.015 } else { 0.01 };
            assert!((volume - paper).abs() < tol, "{row} {shape}: {volume} vs paper {paper}");
        }
    }
    let chair =
        |row: &str| lines.iter().find(|l| l[0] == row && l[4] == "chair_101").unwrap()[5].parse::<Real>().unwrap();
    // Hull 0.6558 (SOURCE.md); our box search beats trimesh's face-normal box (1.007).
    assert!((chair("hull") - 0.6558).abs() < 1e-3 && chair("obb") <= 1.007, "{text}");
}

/// The baselines' shapes contain every point of a mesh, and the minimum ball / box are no larger
/// than simple enclosing alternatives (ball around the box center, axis-aligned box).
#[test]
fn baseline_shapes_contain_every_vertex() {
    let pts = mesh::load_points(&psb_dir().join("octopus_121.off")).unwrap();
    let b = baselines(&pts).unwrap();
    assert!(pts.iter().all(|p| b.sphere.contains(p) && b.obb.contains(p) && b.aabb.contains(p)));
    let r_box = pts.iter().map(|p| (p - b.aabb.center).norm()).fold(0.0, Real::max);
    assert!(b.sphere.radius <= r_box);
    assert!(b.obb.volume() <= b.aabb.volume());
    assert!(b.hull.volume < b.obb.volume());
}
