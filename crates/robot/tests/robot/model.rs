//! The URDF model: closed-form poses of one-joint robots, and every malformed description refused
//! naming its element.

use sublevel_core::math::{Isometry3, Vector3};
use sublevel_core::Error;
use sublevel_robot::RobotModel;

/// A robot of two links joined by `joint` (its XML body inside `<joint name="j" …>`).
fn two_links(kind: &str, body: &str) -> String {
    format!(
        r#"<robot name="r"><link name="a"/><link name="b"/>
           <joint name="j" type="{kind}"><parent link="a"/><child link="b"/>{body}</joint></robot>"#
    )
}

fn field_of(result: sublevel_core::Result<RobotModel>) -> String {
    match result {
        Err(Error::InvalidArgument { field, .. }) => field,
        other => panic!("expected InvalidArgument, got {other:?}"),
    }
}

#[test]
fn one_joint_robots_move_as_their_closed_forms() {
    let limit = r#"<limit lower="-1" upper="1" effort="1" velocity="1"/>"#;
    let slide = RobotModel::from_urdf_str(&two_links(
        "prismatic",
        &format!(r#"<origin xyz="0 0 1" rpy="0 0 1.5707963267948966"/><axis xyz="2 0 0"/>{limit}"#),
    ))
    .unwrap();
    // The axis (normalized) is x of the joint frame, turned 90° about z: the world's y.
    let poses = slide.link_poses(&[0.3], &Isometry3::identity()).unwrap();
    assert!((poses[1].translation.vector - Vector3::new(0.0, 0.3, 1.0)).norm() < 1e-15, "{:?}", poses[1]);

    let spin = RobotModel::from_urdf_str(&two_links("continuous", r#"<axis xyz="0 0 1"/>"#)).unwrap();
    let base = Isometry3::translation(1.0, 2.0, 3.0);
    let once = spin.link_poses(&[0.7], &base).unwrap();
    let wrapped = spin.link_poses(&[0.7 + 2.0 * std::f64::consts::PI], &base).unwrap();
    let x = once[1].rotation * Vector3::x();
    assert!((x - Vector3::new(0.7f64.cos(), 0.7f64.sin(), 0.0)).norm() < 1e-15);
    assert!(
        (once[1].rotation.to_rotation_matrix().matrix() - wrapped[1].rotation.to_rotation_matrix().matrix()).norm()
            < 1e-14
    );
    assert_eq!(once[1].translation.vector, Vector3::new(1.0, 2.0, 3.0));

    let hinge = RobotModel::from_urdf_str(&two_links("revolute", &format!(r#"<axis xyz="0 1 0"/>{limit}"#))).unwrap();
    assert!(hinge.check_limits("q", &[0.5]).is_ok());
    match hinge.check_limits("q", &[1.5]) {
        Err(Error::InvalidArgument { field, reason }) => {
            assert_eq!(field, "q[0]");
            assert!(reason.contains("`j`") && reason.contains("[-1, 1]"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(field_of(hinge.link_poses(&[0.1, 0.2], &base).map(|_| hinge.clone())), "q");
    assert_eq!(field_of(hinge.link_poses(&[f64::NAN], &base).map(|_| hinge.clone())), "q[0]");
}

#[test]
fn malformed_descriptions_name_their_element() {
    let limit = r#"<limit lower="-1" upper="1" effort="1" velocity="1"/>"#;
    assert_eq!(field_of(RobotModel::from_urdf_str("<robot name='r'><link name='a'>")), "urdf");
    assert_eq!(field_of(RobotModel::from_urdf_str(&two_links("planar", ""))), "urdf.joint[j].type");
    assert_eq!(
        field_of(RobotModel::from_urdf_str(&two_links(
            "revolute",
            r#"<axis xyz="0 0 0"/><limit lower="0" upper="1" effort="1" velocity="1"/>"#
        ))),
        "urdf.joint[j].axis"
    );
    assert_eq!(
        field_of(RobotModel::from_urdf_str(&two_links(
            "revolute",
            r#"<limit lower="1" upper="-1" effort="1" velocity="1"/>"#
        ))),
        "urdf.joint[j].limit"
    );
    assert_eq!(
        field_of(RobotModel::from_urdf_str(&two_links("revolute", &format!(r#"{limit}<mimic joint="nope"/>"#)))),
        "urdf.joint[j].mimic"
    );
    assert_eq!(
        field_of(RobotModel::from_urdf_str(
            r#"<robot name="r"><link name="a"/><joint name="j" type="fixed"><parent link="a"/><child link="z"/></joint></robot>"#
        )),
        "urdf.joint[j].child"
    );
    assert_eq!(
        field_of(RobotModel::from_urdf_str(r#"<robot name="r"><link name="a"/><link name="b"/></robot>"#)),
        "urdf",
        "two roots"
    );
    let cycle = r#"<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
        <joint name="j1" type="fixed"><parent link="a"/><child link="b"/></joint>
        <joint name="j2" type="fixed"><parent link="c"/><child link="c"/></joint></robot>"#;
    assert_eq!(field_of(RobotModel::from_urdf_str(cycle)), "urdf");
    let twice = r#"<robot name="r"><link name="a"/><link name="b"/>
        <joint name="j1" type="fixed"><parent link="a"/><child link="b"/></joint>
        <joint name="j2" type="fixed"><parent link="a"/><child link="b"/></joint></robot>"#;
    assert_eq!(field_of(RobotModel::from_urdf_str(twice)), "urdf.joint[j2].child");
    let bad_box = r#"<robot name="r"><link name="a"><collision><geometry><box size="1 -2 1"/></geometry></collision></link></robot>"#;
    assert_eq!(field_of(RobotModel::from_urdf_str(bad_box)), "urdf.link[a].collision[0].box.size");
}

#[test]
fn configurations_from_named_columns_fill_the_rest_from_defaults() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/gantry.urdf");
    let gantry = RobotModel::from_urdf_file(&path).unwrap();
    // rail, spin, shoulder, elbow are the configuration's entries; `follow` is a mimic joint.
    assert_eq!(gantry.variable_names(), ["rail", "spin", "shoulder", "elbow"]);
    let defaults = [("shoulder".to_owned(), 0.5), ("not_a_joint".to_owned(), 9.0)];
    let names = ["elbow".to_owned(), "rail".to_owned()];
    let q = gantry.configurations("c", &names, &[1.0, 0.2, 2.0, 0.4], &defaults).unwrap();
    assert_eq!(q, [vec![0.2, 0.0, 0.5, 1.0], vec![0.4, 0.0, 0.5, 2.0]]);
    // No names: every entry, in order; the continuous `spin` takes any value, the limits are states.
    let q = gantry.configurations("c", &[], &[0.8, 100.0, -2.0, 2.5], &[]).unwrap();
    assert_eq!(q, [vec![0.8, 100.0, -2.0, 2.5]]);
    let err = |names: &[&str], values: &[f64]| {
        let names: Vec<String> = names.iter().map(|s| (*s).to_owned()).collect();
        match gantry.configurations("c", &names, values, &[]) {
            Err(Error::InvalidArgument { field, .. }) => field,
            other => panic!("expected InvalidArgument, got {other:?}"),
        }
    };
    assert_eq!(err(&["follow"], &[0.0]), "c.joint_names[0]");
    assert_eq!(err(&["tool_mount"], &[0.0]), "c.joint_names[0]");
    assert_eq!(err(&["rail", "rail"], &[0.0, 0.0]), "c.joint_names[1]");
    assert_eq!(err(&["rail", "spin"], &[0.0, 0.0, 0.0]), "c.values");
    assert_eq!(err(&["rail"], &[]), "c.values");
    assert_eq!(err(&["rail", "spin"], &[0.0, f64::NAN]), "c.values[1]");
    // Outside the URDF limits by more than rounding (LIMIT_ROUNDING · max(1, |bound|) = 1e-9 here);
    // a value rounded 1e-12 past the bound is on it.
    assert_eq!(err(&["rail"], &[0.8 + 2e-9]), "c.values[0]");
    assert_eq!(
        gantry.configurations("c", &["rail".to_owned()], &[0.8 + 1e-12], &[]).unwrap(),
        [vec![0.8 + 1e-12, 0.0, 0.0, 0.0]]
    );
    assert_eq!(err(&["spin", "shoulder"], &[100.0, -2.5]), "c.values[1]");
    assert_eq!(err(&["elbow"], &[0.0, 1e300]), "c.values[1]");
}
