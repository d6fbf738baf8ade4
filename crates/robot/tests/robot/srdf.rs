//! SRDF reading: disabled pairs, group states and virtual joints as written, the self-collision
//! pairs they leave, mesh paths resolved as ROS does, and malformed documents refused naming the
//! element.

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
