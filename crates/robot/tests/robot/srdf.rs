//! SRDF reading: disabled pairs, group states and virtual joints as written, the self-collision
//! pairs they leave, mesh paths resolved as ROS does, and malformed documents refused naming the
//! element.

use sublevel_core::math::Real;
use sublevel_core::Error;
use sublevel_robot::srdf::Semantics;
use sublevel_robot::{resolve_mesh_path, RobotModel};

const SRDF: &str = r#"<?xml version="1.0"?>
<robot name="r">
  <group name="arm"><chain base_link="a" tip_link="c"/></group>
  <group_state name="ready" group="arm">
    <joint name="j1" value="0.5"/>
    <joint name="j2" value=" -1.25 "/>
  </group_state>
  <virtual_joint name="world_joint" parent_frame="world" child_link="a" type="fixed"/>
  <disable_collisions link1="a" link2="b" reason="Adjacent"/>
  <disable_collisions link1="c" link2="b" reason="Never"/>
</robot>"#;

/// Four links in a chain, three with a collision box.
const URDF: &str = r#"<robot name="r">
  <link name="a"><collision><geometry><box size="1 1 1"/></geometry></collision></link>
  <link name="b"><collision><geometry><sphere radius="0.1"/></geometry></collision></link>
  <link name="c"><collision><geometry><cylinder radius="0.1" length="0.5"/></geometry></collision></link>
  <link name="d"/>
  <joint name="j1" type="continuous"><parent link="a"/><child link="b"/></joint>
  <joint name="j2" type="continuous"><parent link="b"/><child link="c"/></joint>
  <joint name="j3" type="fixed"><parent link="c"/><child link="d"/></joint>
</robot>"#;

#[test]
fn an_srdf_reads_and_leaves_the_pairs_to_check() {
    let s = Semantics::from_srdf_str(SRDF).unwrap();
    assert_eq!(s.name, "r");
    assert_eq!(s.disabled_pairs.len(), 2);
    assert_eq!((s.disabled_pairs[1].link1.as_str(), s.disabled_pairs[1].reason.as_str()), ("c", "Never"));
    assert_eq!(s.group_states.len(), 1);
    assert_eq!(s.group_states[0].joints, vec![("j1".to_owned(), 0.5), ("j2".to_owned(), -1.25)]);
    assert_eq!(s.virtual_joints[0].child_link, "a");
    let robot = RobotModel::from_urdf_str(URDF).unwrap();
    // Links with geometry: a, b, c → pairs ab, ac, bc; ab and bc are allowed.
    assert_eq!(robot.self_collision_pairs(&s.disabled_pairs).unwrap(), vec![(0, 2)]);
    assert_eq!(robot.self_collision_pairs(&[]).unwrap(), vec![(0, 1), (0, 2), (1, 2)]);
}

#[test]
fn malformed_srdf_names_the_element() {
    let field = |text: &str| match Semantics::from_srdf_str(text) {
        Err(Error::InvalidArgument { field, .. }) => field,
        other => panic!("{other:?}"),
    };
    assert_eq!(field("<robot><disable_collisions link1='a'/></robot>"), "srdf.disable_collisions[0]");
    assert_eq!(
        field("<robot><group_state name='s' group='g'><joint name='j' value='x'/></group_state></robot>"),
        "srdf.group_state[0].joint[0]"
    );
    assert_eq!(field("<robot><virtual_joint name='v'/></robot>"), "srdf.virtual_joint[0]");
    assert_eq!(field("<robot><disable_collisions link1='a' link2='b'></robot>"), "srdf");
    let robot = RobotModel::from_urdf_str(URDF).unwrap();
    let s = Semantics::from_srdf_str("<robot><disable_collisions link1='a' link2='zz'/></robot>").unwrap();
    match robot.self_collision_pairs(&s.disabled_pairs) {
        Err(Error::InvalidArgument { field, reason }) => {
            assert_eq!(field, "srdf.disable_collisions[0]");
            assert!(reason.contains("`zz`"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn mesh_paths_resolve_as_ros_does() {
    let dir = std::env::temp_dir().join(format!("sublevel-mesh-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("pkg/meshes")).unwrap();
    std::fs::write(dir.join("pkg/meshes/l.stl"), b"solid x\nendsolid x\n").unwrap();
    let other = dir.join("elsewhere");
    let found = resolve_mesh_path("m", "package://pkg/meshes/l.stl", None, &[other.clone(), dir.clone()]).unwrap();
    assert_eq!(found, dir.join("pkg/meshes/l.stl"));
    assert_eq!(
        resolve_mesh_path("m", "meshes/l.stl", Some(&dir.join("pkg")), &[]).unwrap(),
        dir.join("pkg/meshes/l.stl")
    );
    let abs = dir.join("pkg/meshes/l.stl");
    assert_eq!(resolve_mesh_path("m", &format!("file://{}", abs.display()), None, &[]).unwrap(), abs);
    match resolve_mesh_path("link[a].collision[0]", "package://pkg/meshes/none.stl", None, &[]) {
        Err(Error::InvalidArgument { field, reason }) => {
            assert_eq!(field, "link[a].collision[0]");
            assert!(reason.contains("--package-dir"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A robot as real URDFs split links: `base` and `base_2` (fixed to it, overlapping), an arm link
/// moved by a revolute joint and a finger fixed to the arm link, with a bound printed at five
/// digits.
const SPLIT_URDF: &str = r#"<robot name="split">
  <link name="base"><collision><geometry><box size="0.4 0.4 0.2"/></geometry></collision></link>
  <link name="base_2"><collision><geometry><box size="0.3 0.3 0.3"/></geometry></collision></link>
  <link name="arm"><collision><origin xyz="0 0 0.5"/><geometry><box size="0.1 0.1 0.5"/></geometry></collision></link>
  <link name="finger"><collision><origin xyz="0 0 0.8"/><geometry><sphere radius="0.05"/></geometry></collision></link>
  <link name="tip"/>
  <joint name="base_fixed" type="fixed"><parent link="base"/><child link="base_2"/></joint>
  <joint name="shoulder" type="revolute"><parent link="base_2"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-3.14159" upper="3.14159" effort="1" velocity="1"/></joint>
  <joint name="finger_fixed" type="fixed"><parent link="arm"/><child link="tip"/></joint>
  <joint name="tip_fixed" type="fixed"><parent link="tip"/><child link="finger"/></joint>
</robot>"#;

/// The bound of ±π as URDFs print it, at five digits.
#[allow(clippy::approx_constant)]
const PRINTED_PI: f64 = 3.14159;

#[test]
fn links_joined_by_fixed_joints_are_one_rigid_body_and_never_checked() {
    let robot = RobotModel::from_urdf_str(SPLIT_URDF).unwrap();
    let id = |n: &str| robot.link_index(n).unwrap();
    let body = robot.rigid_bodies();
    assert_eq!(body[id("base")], body[id("base_2")]);
    // A chain of two fixed joints through a link without geometry is still one body.
    assert_eq!(body[id("arm")], body[id("finger")]);
    assert_ne!(body[id("base")], body[id("arm")]);
    let pair = |a: &str, b: &str| (id(a).min(id(b)), id(a).max(id(b)));
    assert_eq!(robot.rigid_pairs(), vec![pair("base", "base_2"), pair("arm", "finger")]);
    // Of the 6 pairs of the four links with geometry, the two rigid ones are left out; the SRDF
    // allowing one of them changes nothing, and the summary lists only the one it did not allow.
    let pairs = robot.self_collision_pairs(&[]).unwrap();
    assert_eq!(pairs.len(), 4);
    assert!(!pairs.contains(&pair("base", "base_2")) && !pairs.contains(&pair("arm", "finger")));
    let s = Semantics::from_srdf_str("<robot><disable_collisions link1='base_2' link2='base'/></robot>").unwrap();
    assert_eq!(robot.self_collision_pairs(&s.disabled_pairs).unwrap(), pairs);
    let allowed = [["base_2".to_owned(), "base".to_owned()]];
    assert_eq!(robot.rigid_pairs_not_in(&allowed), vec![["arm".to_owned(), "finger".to_owned()]]);
}

#[test]
fn srdf_entries_naming_links_or_joints_the_urdf_lacks_are_skipped_with_a_warning() {
    let robot = RobotModel::from_urdf_str(SPLIT_URDF).unwrap();
    let s = Semantics::from_srdf_str(
        r#"<robot name="split">
          <disable_collisions link1="base" link2="arm" reason="Adjacent"/>
          <disable_collisions link1="bellows_link2" link2="arm" reason="Never"/>
          <disable_collisions link1="ghost_a" link2="ghost_b" reason="Never"/>
          <group_state name="home" group="arm"><joint name="shoulder" value="0.5"/><joint name="elbow" value="1"/>
            <joint name="root_joint" value="0. 0. 1.01927 0. 0. 0. 1."/></group_state>
        </robot>"#,
    )
    .unwrap();
    let (kept, warnings) = s.known_to(&robot);
    assert_eq!(kept.disabled_pairs.len(), 1);
    assert_eq!((kept.disabled_pairs[0].link1.as_str(), kept.disabled_pairs[0].link2.as_str()), ("base", "arm"));
    assert_eq!(kept.group_states[0].joints, vec![("shoulder".to_owned(), 0.5)]);
    assert_eq!(
        s.group_states[0].multi_dof,
        vec![("root_joint".to_owned(), vec![0.0, 0.0, 1.01927, 0.0, 0.0, 0.0, 1.0])]
    );
    assert!(kept.group_states[0].multi_dof.is_empty());
    assert_eq!(warnings.len(), 4, "{warnings:?}");
    assert!(warnings[3].starts_with("srdf.group_state[0]: skipped joint `root_joint` of 7 values"), "{}", warnings[3]);
    assert!(warnings[0].starts_with("srdf.disable_collisions[1]:") && warnings[0].contains("`bellows_link2`"));
    assert!(warnings[1].starts_with("srdf.disable_collisions[2]:") && warnings[1].contains("`ghost_a` and `ghost_b`"));
    assert!(warnings[2].starts_with("srdf.group_state[0].joint[1]:") && warnings[2].contains("`elbow`"));
    // What is kept leaves base–arm unchecked: base_2–arm, base–finger, base_2–finger remain.
    assert_eq!(robot.self_collision_pairs(&kept.disabled_pairs).unwrap().len(), 3);
}

#[test]
fn a_value_within_rounding_of_a_limit_is_within_it() {
    let robot = RobotModel::from_urdf_str(SPLIT_URDF).unwrap();
    let joint = robot.variable_joint(0);
    // LIMIT_ROUNDING · max(1, |bound|): 3.1e-9 here.
    for (v, admitted) in [
        (PRINTED_PI, true),
        (-PRINTED_PI, true),
        (PRINTED_PI + 3.0e-9, true),
        (-PRINTED_PI - 3.0e-9, true),
        (PRINTED_PI + 4.0e-9, false),
        (-std::f64::consts::PI, false),
        (Real::NAN, false),
    ] {
        assert_eq!(joint.admits(v), admitted, "{v}");
        assert_eq!(robot.check_limits("q", &[v]).is_ok(), admitted, "{v}");
    }
    assert_eq!(joint.clamp(3.2), PRINTED_PI);
    let names = vec!["shoulder".to_owned()];
    assert!(robot.configurations("c", &names, &[PRINTED_PI + 3.0e-9], &[]).is_ok());
    match robot.configurations("c", &names, &[0.0, -3.2], &[]) {
        Err(Error::InvalidArgument { field, .. }) => assert_eq!(field, "c.values[1]"),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        robot.configurations_outside_limits("c", &names, &[0.0, -3.2], &[]).unwrap(),
        vec![vec![0.0], vec![-3.2]]
    );
}
