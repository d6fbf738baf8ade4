//! Margin queries at margin 0: contact counts as closer.

use super::*;

#[test]
fn a_zero_margin_counts_overlapping_models_as_closer() {
    // Margin 0 asks for contact: overlapping models (brute-force distance 0) are closer, as a
    // single pair's collide answer says; separated ones are not.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let (ta, _) = sphere_tree(30);
    let (tb, _) = sphere_tree(40);
    let (mut overlapping, mut separated) = (0, 0);
    for case in 0..40 {
        let pa = random_pose(&mut rng, 0.2);
        let pb = Isometry3::from_parts(
            Vector3::new(rng.random_range(0.0..3.0), rng.random_range(-0.5..0.5), 0.0).into(),
            random_rotation(&mut rng),
        );
        let (exact, _) = brute_force(&ta, &pa, &tb, &pb);
        if exact > 0.0 && exact < 1e-9 {
            continue;
        }
        let r = tree_closer_than(&ta, &pa, &tb, &pb, 0.0, None, &TreeQueryParams::default()).unwrap();
        assert!(r.converged);
        assert_eq!(r.closer, exact == 0.0, "case {case}: brute force {exact}, {r:?}");
        if r.closer {
            overlapping += 1;
            assert_eq!(r.bound, 0.0);
        } else {
            separated += 1;
            assert!(r.bound > 0.0 && r.bound <= exact + 1e-9, "{r:?}");
        }
    }
    assert!(overlapping >= 5 && separated >= 5, "{overlapping} overlapping, {separated} separated");
}
