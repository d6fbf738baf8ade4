//! The stability suite (`sublevel-lab stability`) on the bundled chair / human fits at 2d = 2 and
//! 4 (degree 6 and 8 only in `sublevel-lab stability`, to keep this test a few seconds).
//!
//! Every query of every case (tiny gaps 1e-9 … 1e-1, tangency, deep and concentric overlap,
//! containment, identical bodies, slabs and needles with axis ratio 1e-3, 1e4 m offsets, warm
//! starts across huge pose jumps, rotations near 180°, bodies scaled to 1 cm) must be either
//! **certified** (Newton agrees with the level-0 SDP: |n − s| ≤ 1e-6·|s| or ≤ 1e-9 absolute, on
//! the squared distance in m² and on d(p₁‖p₂)) or **flagged** (answered by a verified SDP
//! fallback).

use super::suite::{run_case, stability_cases};
use std::path::PathBuf;
use sublevel_core::Body;
use sublevel_query::CertifyParams;

fn load(file: &str) -> Body {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..").join("tests").join("data").join(file);
    Body::load(&p).unwrap()
}

#[test]
fn every_hard_case_is_certified_or_flagged_with_a_verified_fallback() {
    let bodies: Vec<Body> =
        ["chair_101.deg2.json", "human_10.deg2.json", "chair_101.deg4.json", "human_10.deg4.json"].map(load).into();
    let cases = stability_cases(&bodies, &[], 2, 7).unwrap();
    assert!(cases.len() >= 15, "{} cases", cases.len());
    let params = CertifyParams::default();
    let mut failures = Vec::new();
    let (mut total, mut certified, mut flagged) = (0, 0, 0);
    for case in &cases {
        let r = run_case(case, &params);
        eprintln!(
            "{:<36} n {:>3}  certified {:>5.1}%  flagged {:>5.1}%  median it {:>5.1}  max rel err {:.1e}  max abs err ≈0 {:.1e}",
            r.name,
            r.n,
            r.certified_percent(),
            r.flagged_percent(),
            r.median_iterations,
            r.max_relative_error,
            r.max_absolute_error_near_zero
        );
        assert_eq!(r.n, 2 * case.pairs.len());
        total += r.n;
        certified += r.certified;
        flagged += r.flagged;
        for f in &r.failures {
            eprintln!("    {f}");
        }
        if r.unresolved > 0 {
            failures.extend(r.failures.iter().filter(|f| f.contains("UNRESOLVED")).cloned());
        }
    }
    eprintln!("stability: {certified} certified + {flagged} flagged of {total} queries");
    assert!(failures.is_empty(), "unresolved queries:\n{}", failures.join("\n"));
    // The fallback is the exception: most answers are Newton's, checked.
    assert!(certified * 10 >= total * 8, "only {certified} of {total} certified");
}

#[test]
fn the_batch_answers_every_hard_case_as_one_pair_at_a_time() {
    // The batch solver (eight single-precision lanes, then four double-precision ones) on the
    // suite's hard configurations, each pair repeated 12 times in one batch, at 2d = 4, 6, 8:
    // every answer with the single-pair solver's convergence, overlap flag, distance (to 1e-9 of
    // 1 + the distance, meters) and witnesses (to 1e-6 of the bodies' sizes).
    use sublevel_query::{batch::cold_distances, distance, NewtonParams};
    let bodies: Vec<Body> = [
        "chair_101.deg4.json",
        "human_10.deg4.json",
        "chair_101.deg6.json",
        "human_10.deg6.json",
        "chair_101.deg8.json",
        "human_10.deg8.json",
    ]
    .map(load)
    .into();
    let params = NewtonParams::default();
    let mut checked = 0;
    for case in stability_cases(&bodies, &[], 2, 11).unwrap() {
        for p in &case.pairs {
            let single = distance(&p.a, &p.pose_a, &p.b, &p.pose_b, None, &params);
            let batch = cold_distances(&p.a, &p.b, &vec![(p.pose_a, p.pose_b); 12], &params, false);
            for d in &batch {
                let what = format!("{}: batch {d:?}\nsingle {single:?}", case.name);
                assert_eq!(d.status.converged(), single.status.converged(), "{what}");
                assert_eq!(d.overlapping, single.overlapping, "{what}");
                assert!((d.distance - single.distance).abs() <= 1e-9 * (1.0 + single.distance), "{what}");
                let size = p.a.scale() + p.b.scale();
                let apart = (d.witness_a - single.witness_a).norm().max((d.witness_b - single.witness_b).norm());
                assert!(apart <= 1e-6 * size, "{what}");
                checked += 1;
            }
        }
    }
    assert!(checked >= 12 * 30, "{checked} answers checked");
}
