//! The catalog against a real redb store: persistence across reopen, warm starts that follow
//! their pair, all-or-nothing pose batches.

use super::*;
use crate::body::ellipsoid;
use crate::math::pose_from_parts;
use crate::scene::store::RedbStore;

fn at(x: f64) -> Isometry3 {
    pose_from_parts("pose", [1.0, 0.0, 0.0, 0.0], [x, 0.0, 0.0]).unwrap()
}

fn open(dir: &std::path::Path) -> Catalog {
    Catalog::open(Box::new(RedbStore::open_dir(dir).unwrap()), NewtonParams::default()).unwrap()
}

#[test]
fn catalog_persists_and_warm_starts_follow_the_pair() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, i1, i2);
    {
        let c = open(dir.path());
        let b1 = c.add_body("r1", ellipsoid([0.0; 3], [0.5; 3]).unwrap()).unwrap();
        let b2 = c.add_body("r2", ellipsoid([0.0; 3], [0.25; 3]).unwrap()).unwrap();
        scene = c.create_scene("s").unwrap();
        i1 = c.add_instance(&scene, &b1, at(0.0)).unwrap();
        i2 = c.add_instance(&scene, &b2, at(2.0)).unwrap();
        // Spheres: distance = ‖c₁ − c₂‖ − r₁ − r₂.
        let d = c.distance(&scene, &i1, &i2).unwrap();
        assert!((d.distance - 1.25).abs() < 1e-9, "{}", d.distance);
        assert!(!d.warm_started);
        c.set_poses(&scene, &[(i2.clone(), at(1.5))]).unwrap();
        let d = c.distance(&scene, &i1, &i2).unwrap();
        assert!((d.distance - 0.75).abs() < 1e-9, "{}", d.distance);
        assert!(d.warm_started);
        // Growth of spheres: (‖c₁ − c₂‖ − r₂)² / r₁².
        let g = c.growth(&scene, &i1, &i2).unwrap();
        assert!((g.value - (1.25f64 / 0.5).powi(2)).abs() < 1e-9, "{}", g.value);
        assert_eq!(c.cached_warm_starts(&scene).unwrap(), 2);
        // A bad batch entry changes nothing; an unknown instance is NotFound.
        let err = c.set_poses(&scene, &[(i2.clone(), at(9.0)), ("i-nope".into(), at(0.0))]).unwrap_err();
        assert!(err.to_string().contains("poses[1].instance_id"), "{err}");
        assert!(matches!(c.distance(&scene, &i1, "i-nope"), Err(Error::NotFound { .. })));
        // The body is in use.
        assert!(
            matches!(c.delete_body(&b1), Err(Error::FailedPrecondition(m)) if m.contains("remove the instance first"))
        );
    }
    let c = open(dir.path());
    let v = c.get_scene(&scene).unwrap();
    assert_eq!(v.instances.len(), 2);
    let p2 = v.instances.iter().find(|i| i.id == i2).unwrap().pose;
    assert!((p2.translation.vector.x - 1.5).abs() < 1e-15, "the failed batch must not have moved i2");
    assert_eq!(c.cached_warm_starts(&scene).unwrap(), 0, "warm starts are memory only");
    let d = c.distance(&scene, &i1, &i2).unwrap();
    assert!((d.distance - 0.75).abs() < 1e-9);
    c.remove_instance(&scene, &i1).unwrap();
    assert_eq!(c.cached_warm_starts(&scene).unwrap(), 0);
    c.delete_scene(&scene).unwrap();
    assert!(matches!(c.get_scene(&scene), Err(Error::NotFound { .. })));
    drop(c);
    let c = open(dir.path());
    assert!(c.get_scene(&scene).is_err());
    assert_eq!(c.bodies().len(), 2);
}
