"""Exact primitives and MoveIt planning scenes against a real server: closed forms, errors naming
their field, and an imported scene with its instances by name, skipped mesh, ACM and robot state."""

import math
from pathlib import Path

import grpc
import numpy as np
import pytest

from sublevel_client import ImportedScene, Pose, Query, SublevelError, quat_from_axis_angle

KITCHEN = """
name: kitchen
robot_state:
  joint_state:
    name: [j1, j2]
    position: [0.5, -1.25]
allowed_collision_matrix:
  entry_names: [hand, table]
  entry_values:
    - [false, true]
    - [true, false]
  default_entry_names: [floor]
  default_entry_values: [true]
world:
  collision_objects:
    - id: table
      header: {frame_id: world}
      pose: {position: [1.0, 0.0, 0.0], orientation: [0, 0, 0, 1]}
      primitives:
        - {type: box, dimensions: [1.2, 1.0, 0.04]}
        - {type: box, dimensions: [0.05, 0.05, 0.7]}
      primitive_poses:
        - position: [0, 0, 0.72]
        - position: [0.5, 0.4, 0.35]
    - id: can
      primitives: [{type: cylinder, dimensions: [0.12, 0.03]}]
      primitive_poses: [{position: [1.0, 0.0, 0.80]}]
    - id: floor
      planes: [{coef: [0, 0, 1, 0]}]
      plane_poses: [{}]
    - id: mug
      meshes:
        - vertices: [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]
          triangles: [{vertex_indices: [0, 1, 2]}, {vertex_indices: [0, 1, 3]}]
      mesh_poses: [{position: [1.2, 0.1, 0.74]}]
"""


def test_primitives_answer_their_closed_forms(client):
    cube = client.upload_primitive("box", size=(1.0, 1.0, 1.0), name="cube")
    ball = client.upload_primitive("sphere", radius=0.25)
    floor = client.upload_primitive("halfspace", normal=(0, 0, 1), offset=0.0)
    summaries = {b.body_id: b for b in client.list_bodies()}
    assert (summaries[cube].primitive, summaries[cube].degree, summaries[cube].name) == ("box", 0, "cube")
    assert summaries[ball].name == "sphere"
    assert client.get_body_json(cube) == '{"primitive":"box","size":[1.0,1.0,1.0]}'

    scene = client.create_scene("primitives")
    turned = Pose(quat=quat_from_axis_angle((0, 0, 1), math.pi / 4), t=(0, 0, 1))
    a = client.add_instance(scene, cube, turned)
    b = client.add_instance(scene, ball, Pose(t=(2, 0, 1)))
    f = client.add_instance(scene, floor, Pose())
    d = client.distance(scene, a, b, with_gradient=True)
    # The turned cube's corner faces the ball: 2 - sqrt(1/2) - 0.25.
    assert d.distance == pytest.approx(2 - math.sqrt(0.5) - 0.25, abs=1e-12)
    assert d.converged
    np.testing.assert_allclose(d.witness_b, [1.75, 0, 1], atol=1e-12)
    np.testing.assert_allclose(d.gradient_b[:3], [1, 0, 0], atol=1e-9)
    assert client.distance(scene, f, a).distance == pytest.approx(0.5, abs=1e-12)
    near, far = client.query(scene, queries=[Query.collide(a, b, margin=1.1), Query.collide(a, b, margin=1.0)]).answers
    assert near.collides and not far.collides
    pairs = client.check_scene(scene, margin=0.6).pairs
    assert {(p.first, p.second) for p in pairs} == {tuple(sorted((a, f)))}


def test_bad_primitives_and_growth_are_refused_naming_the_field(client):
    with pytest.raises(SublevelError) as e:
        client.upload_primitive("box", size=(1.0, -2.0, 1.0))
    assert (e.value.code, e.value.field) == (grpc.StatusCode.INVALID_ARGUMENT, "primitive.size[1]")
    with pytest.raises(SublevelError) as e:
        client.upload_primitive("sphere", radius=0.5, height=1.0)
    assert e.value.field == "primitive.height"
    with pytest.raises(ValueError):
        client.upload_primitive("torus", radius=1.0)
    cube = client.upload_primitive("box", size=(1, 1, 1))
    scene = client.create_scene("growth")
    a = client.add_instance(scene, cube, Pose())
    b = client.add_instance(scene, cube, Pose(t=(3, 0, 0)))
    with pytest.raises(SublevelError) as e:
        client.growth(scene, a, b)
    assert (e.value.code, e.value.field) == (grpc.StatusCode.INVALID_ARGUMENT, "instance_1")


def test_a_planning_scene_imports_with_its_instances_by_name(client, tmp_path):
    path = tmp_path / "kitchen.yaml"
    path.write_text(KITCHEN)
    r = client.import_scene(path, skip_meshes=True)
    assert isinstance(r, ImportedScene)
    assert r.name == "kitchen"
    assert [(i.name, i.kind) for i in r.instances] == [
        ("table#0", "box"),
        ("table#1", "box"),
        ("can", "cylinder"),
        ("floor", "halfspace"),
    ]
    assert (r.objects, r.bodies) == (4, 4)
    assert [(s.object_id, s.kind) for s in r.skipped] == [("mug", "mesh")]
    np.testing.assert_allclose(r.skipped[0].pose.t, [1.2, 0.1, 0.74])
    assert r.joint_positions == {"j1": 0.5, "j2": -1.25}
    acm = r.allowed_collision
    assert acm.allowed("hand", "table") and not acm.allowed("hand", "hand") and acm.allowed("hand", "floor")
    np.testing.assert_allclose(r.instances[0].pose.t, [1.0, 0.0, 0.72])
    ids = r.ids
    # The can (bottom at 0.74) stands 0.0 m on the table top (0.72 + 0.02): touching.
    assert client.distance(r.scene_id, ids["table#0"], ids["can"]).distance == pytest.approx(0.0, abs=1e-12)
    # The tabletop's underside (0.70) above the floor.
    assert client.distance(r.scene_id, ids["floor"], ids["table#0"]).distance == pytest.approx(0.70, abs=1e-12)
    # The same scene as bytes, named.
    again = client.import_scene(KITCHEN.encode(), name="copy", skip_meshes=True)
    assert again.name == "copy" and again.scene_id != r.scene_id
    assert again.meshes == []


BOX_MESH_SCENE = Path(__file__).resolve().parents[3] / "tests" / "data" / "box_mesh.scene.yaml"


def test_a_planning_scene_mesh_is_fitted_and_placed_when_waited_for(client):
    # tests/data/box_mesh.scene.yaml: a closed box mesh under an object pose and a mesh pose,
    # composed at (1, 2.1, 0.7) with quaternion (1/2, 1/2, 1/2, 1/2); a ball beside it.
    updates = []
    r = client.import_scene(BOX_MESH_SCENE, mesh_tolerance=0.02, wait=True, progress=updates.append)
    assert r.skipped == []
    assert [(m.name, m.object_id, m.vertices, m.triangles) for m in r.meshes] == [("crate", "crate", 8, 12)]
    mesh = r.meshes[0]
    assert mesh.state == "SUCCEEDED" and mesh.body_id, mesh
    assert "`crate` added" in mesh.message
    assert updates and updates[-1].job_id == mesh.job_id
    np.testing.assert_allclose(mesh.pose.t, [1.0, 2.1, 0.7], atol=1e-15)
    ids = r.ids
    assert set(ids) == {"ball", "crate"}
    placed = {i.instance_id: i for i in client.get_scene(r.scene_id).instances}
    assert placed[ids["crate"]].body_id == mesh.body_id
    np.testing.assert_allclose(placed[ids["crate"]].pose.t, [1.0, 2.1, 0.7], atol=1e-15)
    # The box spans [1, 1.3] x [2.0, 2.2] x [0.65, 0.75]; the ball (r 0.05) is (0.2, 0.2, 0.15)
    # from it. The fitted body contains the box: at most the exact distance.
    exact = math.sqrt(0.2**2 + 0.2**2 + 0.15**2) - 0.05
    d = client.distance(r.scene_id, ids["crate"], ids["ball"]).distance
    assert exact - 0.1 < d <= exact + 1e-9


def test_a_bad_planning_scene_names_its_field(client):
    bad = "world:\n  collision_objects:\n    - id: o\n      primitives: [{type: box, dimensions: [1, 2]}]\n      primitive_poses: [{}]\n"
    with pytest.raises(SublevelError) as e:
        client.import_scene(bad)
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert e.value.field == "yaml.world.collision_objects[0].primitives[0].dimensions"
    with pytest.raises(SublevelError) as e:
        client.import_scene('{"world": {"collision_objects": [{"id": "o"}]}}')
    assert e.value.field == "json.world.collision_objects[0]"
