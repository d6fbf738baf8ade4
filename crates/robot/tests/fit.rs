//! Robot fits: one body per mesh by default (what the checks read), compound trees with
//! `leaves`, and the fallback path when a fit fails numerically — each checked against the mesh
//! it must contain (every vertex inside the body, verified when the robot is read) and against
//! the closed-form distances of the slider's cubes.

use sublevel_core::math::{Isometry3, Real};
use sublevel_robot::{fit_robot, CheckOptions, FittedRobot, LinkShape, RobotChecker, RobotFitSettings};

/// The unit cube [−0.5, 0.5]³ (OBJ quads).
const CUBE: &str = include_str!("data/cube.obj");

/// Fits the slider of `data/slider.urdf` (two cube meshes, one box) with `edit` applied to the
/// settings, no cache, no clearance tables.
fn slider(edit: impl FnOnce(&mut RobotFitSettings)) -> FittedRobot {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE).unwrap();
    std::fs::write(dir.path().join("slider.urdf"), include_str!("data/slider.urdf")).unwrap();
    let mut settings = RobotFitSettings::default();
    edit(&mut settings);
    fit_robot(&dir.path().join("slider.urdf"), None, &settings, &|_| {}).unwrap()
}

/// Leaves of each mesh's compound body.
fn leaves(robot: &FittedRobot) -> Vec<usize> {
    robot.file.geometries.iter().filter_map(|g| g.compound.as_ref()).map(|c| c.nodes.len()).collect()
}

/// The slider's distance to a wall at x = 1.2 (a box of half side 0.1) at `slide`: exact.
fn wall_distance(robot: &FittedRobot, slide: Real) -> Real {
    let wall = sublevel_robot::WorldObject::primitive(
        "wall",
        sublevel_core::primitive::Primitive::Box { half_extents: sublevel_core::math::Vector3::new(0.1, 0.1, 0.1) },
        sublevel_core::math::pose_from_parts("wall", [1.0, 0.0, 0.0, 0.0], [1.2, 0.0, 0.0]).unwrap(),
    );
    let mut checker = RobotChecker::new(robot, vec![wall], &|_, _| None).unwrap();
    let options = CheckOptions { distance: true, ..CheckOptions::default() };
    let mut q = vec![0.0; robot.model.dof()];
    q[0] = slide;
    checker.check(&q, &Isometry3::identity(), &options).unwrap().distance
}

#[test]
fn one_body_per_mesh_by_default_and_trees_with_leaves() {
    let plain = slider(|_| {});
    assert_eq!(leaves(&plain), [1, 1], "one body per mesh");
    assert!(plain.file.report.fallbacks.is_empty(), "{:?}", plain.file.report.fallbacks);
    let trees = slider(|s| {
        s.leaves = true;
        s.compound.excess_tolerance = Some(0.01);
        s.compound.max_parts = 4;
    });
    assert!(leaves(&trees).iter().all(|&n| n >= 1));
    // Both answer the meshes' distances: the checks' exact stage decides near pairs.
    for slide in [-0.2, 0.0, 0.3] {
        let exact = 0.5 - slide;
        for robot in [&plain, &trees] {
            let d = wall_distance(robot, slide);
            assert!((d - exact).abs() <= 1e-9, "slide {slide}: {d} vs {exact}");
        }
    }
}

/// A first fit that cannot converge (one interior-point iteration) takes the fallback path:
/// lower degrees with the default solver settings. The report names the mesh; the body still
/// contains every vertex (checked when the robot is read) and the distances stay exact.
#[test]
fn a_fit_that_fails_numerically_takes_the_documented_fallback() {
    let robot = slider(|s| s.compound.fit.max_solver_iterations = 1);
    let fallbacks = &robot.file.report.fallbacks;
    // The cube at its two scales: two distinct meshes, both through the fallback.
    assert_eq!(fallbacks.len(), 2, "{fallbacks:?}");
    assert!(fallbacks.iter().all(|f| f.starts_with("cube.obj") && f.contains("fallback")), "{fallbacks:?}");
    for g in &robot.geometries {
        if let LinkShape::Mesh { body, .. } = &g.shape {
            assert!(body.degree() <= 4, "the fallback's degrees are 2 and 4, got {}", body.degree());
        }
    }
    for slide in [-0.2, 0.3] {
        let d = wall_distance(&robot, slide);
        assert!((d - (0.5 - slide)).abs() <= 1e-9, "slide {slide}: {d}");
    }
}

/// The corner tetrahedron {x, y, z ≥ 0, x + y + z ≤ 1}, faces wound outward.
const TETRAHEDRON: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

/// A link holding the tetrahedron at `scale` (a negative entry mirrors it, as URDFs give one side
/// of a symmetric robot), fitted.
fn tetrahedron_robot(scale: &str) -> FittedRobot {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("tet.obj"), TETRAHEDRON).unwrap();
    let urdf = format!(
        r#"<robot name="tet"><link name="base"/>
          <link name="tet"><collision><geometry><mesh filename="tet.obj" scale="{scale}"/></geometry></collision></link>
          <joint name="lift" type="prismatic"><parent link="base"/><child link="tet"/><axis xyz="0 0 1"/>
            <limit lower="0" upper="1" effort="1" velocity="1"/></joint></robot>"#
    );
    std::fs::write(dir.path().join("tet.urdf"), urdf).unwrap();
    fit_robot(&dir.path().join("tet.urdf"), None, &RobotFitSettings::default(), &|_| {}).unwrap()
}

#[test]
fn a_negative_mesh_scale_mirrors_the_mesh_and_keeps_its_faces_outward() {
    // A box around (0.1, 0.3, 0.1), on the face x + y + z = 0.5 of the tetrahedron scaled by 0.5:
    // touched by it, 0.25 m from its mirror in y (the face y = 0).
    let cube = sublevel_robot::WorldObject::primitive(
        "cube",
        sublevel_core::primitive::Primitive::Box { half_extents: sublevel_core::math::Vector3::new(0.05, 0.05, 0.05) },
        sublevel_core::math::pose_from_parts("cube", [1.0, 0.0, 0.0, 0.0], [0.1, 0.3, 0.1]).unwrap(),
    );
    let options = CheckOptions { distance: true, ..CheckOptions::default() };
    for (scale, collides) in [("0.5 0.5 0.5", true), ("0.5 -0.5 0.5", false)] {
        let robot = tetrahedron_robot(scale);
        let mesh = robot.file.geometries[0].mesh.as_ref().unwrap();
        // The stored mesh's signed volume: positive (faces outward), 0.5³ / 6.
        let p = |i: u32| sublevel_core::math::Vector3::from(mesh.vertices[i as usize]);
        let volume: Real = mesh.triangles.iter().map(|t| p(t[0]).dot(&p(t[1]).cross(&p(t[2]))) / 6.0).sum();
        assert!((volume - 0.125 / 6.0).abs() < 1e-12, "scale {scale}: signed volume {volume}");
        let mut checker = RobotChecker::new(&robot, vec![cube.clone()], &|_, _| None).unwrap();
        let answer = checker.check(&[0.0], &Isometry3::identity(), &options).unwrap();
        assert_eq!(answer.collides, collides, "scale {scale}");
        if !collides {
            assert!((answer.distance - 0.25).abs() < 1e-9, "{}", answer.distance);
        }
    }
}
