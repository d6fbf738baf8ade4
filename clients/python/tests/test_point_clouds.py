"""Point-cloud obstacles (UpdatePointCloud) against closed forms and brute force: numpy points
around the one-joint arm's ball (colliding and free configurations, distances), a depth image of
a flat wall rendered by hand (every point where the sensor sees it), replacement and removal with
the scene version, and the errors' fields."""

import math
from pathlib import Path

import grpc
import numpy as np
import pytest

from sublevel_client import FilterCounts, PointCloudInfo, PointCloudUpdate, Pose, SublevelError
from sublevel_client._pb.sublevel.v1 import sublevel_pb2 as pb
from sublevel_client.poses import quat_from_axis_angle, quat_to_matrix

# The arm: a revolute joint `j` about z at the base; link `arm` holds a ball of radius RA at
# (L, 0, 0) of its frame.
L, RA = 0.5, 0.1
ARM = Path(__file__).resolve().parents[3] / "tests" / "data" / "arm.robot.json"
R = 0.01  # the clouds' noise radius

# The sensor: 1.2 m above the origin, turned 0.3 rad about x.
SENSOR = Pose(quat=quat_from_axis_angle((1.0, 0.0, 0.0), 0.3), t=(0.1, -0.2, 1.2))


def to_world(points):
    """Sensor-frame points (N, 3) mapped into the world by SENSOR."""
    return np.asarray(points) @ quat_to_matrix(SENSOR.quat).T + np.asarray(SENSOR.t)


def to_sensor(points):
    """World points (N, 3) in SENSOR's frame."""
    return (np.asarray(points) - np.asarray(SENSOR.t)) @ quat_to_matrix(SENSOR.quat)


def arm_ball(j):
    return np.array([L * math.cos(j), L * math.sin(j), 0.0])


@pytest.fixture(scope="module")
def cell(client):
    """(robot id, scene id): the arm uploaded and placed in a new scene."""
    robot = client.upload_robot(ARM.read_bytes())
    scene = client.create_scene("point cloud cell")
    client.set_scene_robot(scene, robot.robot_id)
    yield robot.robot_id, scene
    client.delete_scene(scene)
    client.delete_robot(robot.robot_id)


def ring(radius=0.12, n=72):
    """World points on a circle of ``radius`` about the arm's ball at j = 0 (z = 0)."""
    a = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return arm_ball(0.0) + radius * np.stack([np.cos(a), np.sin(a), np.zeros(n)], axis=1)


def test_numpy_points_collide_where_brute_force_says(client, cell):
    _, scene = cell
    world = ring()
    sensed = to_sensor(world)
    with_holes = np.vstack([sensed, [[np.nan, 0.0, 1.0], [0.0, np.inf, 1.0]]])
    r = client.update_point_cloud(scene, "camera", points=with_holes, sensor_pose=SENSOR, noise_radius=R, voxel=0.0)
    assert isinstance(r, PointCloudUpdate) and isinstance(r.counts, FilterCounts)
    assert (r.counts.input, r.counts.holes, r.counts.kept, r.counts.voxel) == (74, 2, 72, 0)
    assert r.memory_bytes > 0 and r.seconds >= 0.0

    js = np.array([0.0, 0.05, 0.1, 0.5, 1.5])
    got = client.check_configurations(None, js[:, None], scene=scene, distance=True)
    assert got.scene_version == r.scene_version
    for k, j in enumerate(js):
        gap = np.min(np.linalg.norm(world - arm_ball(j), axis=1)) - RA - R
        assert bool(got.collides[k]) == (gap <= 0.0), (j, gap)
        if gap > 0:
            assert abs(got.distance[k] - gap) < 1e-6, (j, got.distance[k], gap)
            assert got.world_object[k] == "camera"
    # j = 0: 1 cm between the ball and the point balls (free); j = 0.1 is inside the ring.
    assert not got.collides[0] and got.collides[2]

    info = client.get_scene(scene)
    assert info.scene_version == r.scene_version
    (cloud,) = info.point_clouds
    assert isinstance(cloud, PointCloudInfo)
    assert (cloud.name, cloud.points, cloud.noise_radius, cloud.version) == ("camera", 72, R, r.scene_version)

    # Replaced by a ring out of reach: the verdict changes and the version moves on.
    far = client.update_point_cloud(scene, "camera", points=to_sensor(ring() + [0, 0, 1.0]), sensor_pose=SENSOR)
    assert far.scene_version == r.scene_version + 1
    got = client.check_configurations(None, [[0.1]], scene=scene)
    assert not got.collides[0] and got.scene_version == far.scene_version
    # A sampled motion sweeping through the old ring is free now.
    motion = client.check_motions(None, [[0.0]], [[0.3]], scene=scene)
    assert motion.valid[0] and motion.scene_version == far.scene_version
    assert client.remove_point_cloud(scene, "camera") == far.scene_version + 1
    assert client.get_scene(scene).point_clouds == []


def wall_points(h, w, fx, fy, cx, cy, depth=1.0):
    """A flat wall at ``depth`` m deprojected by hand: pixel (u, v) at ((u − cx) d / fx,
    (v − cy) d / fy, d) in the sensor frame, row-major."""
    v, u = np.mgrid[0:h, 0:w]
    return np.stack([(u - cx) * depth / fx, (v - cy) * depth / fy, np.full((h, w), depth)], axis=-1).reshape(-1, 3)


@pytest.mark.parametrize("dtype", ["uint16", "float32"])
def test_a_depth_image_of_a_wall_lands_where_the_sensor_sees_it(client, dtype):
    scene = client.create_scene("wall")
    try:
        h, w, fx, fy, cx, cy = 48, 64, 60.0, 60.0, 31.5, 23.5
        depth = np.full((h, w), 1000, dtype=np.uint16) if dtype == "uint16" else np.ones((h, w), dtype=np.float32)
        depth[0, 0] = 0  # a hole
        r = client.update_point_cloud(
            scene, "wall", depth=depth, fx=fx, fy=fy, cx=cx, cy=cy, sensor_pose=SENSOR, noise_radius=R, voxel=0.0
        )
        assert (r.counts.input, r.counts.holes, r.counts.kept) == (h * w, 1, h * w - 1)
        # Every kept point at z = 1 in the sensor frame: a ball probing the wall from the sensor's
        # side measures the distance to the nearest point of the hand-made wall.
        wall = to_world(wall_points(h, w, fx, fy, cx, cy)[1:])
        ball = client.upload_primitive("sphere", radius=0.05)
        probe = to_world([[0.013, -0.021, 0.8]])[0]
        i = client.add_instance(scene, ball, Pose(t=probe))
        check = client.check_scene(scene, margin=0.5)
        (pair,) = [p for p in check.pairs if p.first == i and p.second == "wall"]
        want = np.min(np.linalg.norm(wall - probe, axis=1)) - 0.05 - R
        assert abs(pair.distance.distance - want) < 1e-6, (pair.distance.distance, want)
        assert abs(want - (0.2 - 0.06)) < 1e-3  # the wall is 0.2 m beyond the probe
        assert check.scene_version == client.get_scene(scene).scene_version
    finally:
        client.delete_scene(scene)


def test_bad_frames_are_refused_naming_their_field(client, cell):
    _, scene = cell
    with pytest.raises(ValueError, match="points"):
        client.update_point_cloud(scene, "c", points=np.zeros((4, 2)))
    with pytest.raises(ValueError, match="exactly one"):
        client.update_point_cloud(scene, "c")
    with pytest.raises(ValueError, match="`fx`"):
        client.update_point_cloud(scene, "c", depth=np.zeros((2, 2), dtype=np.uint16))
    with pytest.raises(ValueError, match="depth"):
        client.update_point_cloud(scene, "c", depth=np.zeros((2, 2), dtype=np.int32), fx=1, fy=1, cx=0, cy=0)

    def refused(req):
        with pytest.raises(SublevelError) as e:
            client._call("UpdatePointCloud", req)
        return e.value

    # Sizes the server checks: a PointCloud2 whose data is no whole number of points, a depth
    # image whose bytes are not width × height pixels.
    odd = pb.UpdatePointCloudRequest(scene_id=scene, name="c", points=pb.PackedPoints(data=b"\0" * 13))
    e = refused(odd)
    assert (e.code, e.field) == (grpc.StatusCode.INVALID_ARGUMENT, "points.data")
    short = pb.DepthImage(width=4, height=3, fx=1, fy=1, depth_u16=b"\0" * 23)
    e = refused(pb.UpdatePointCloudRequest(scene_id=scene, name="c", depth=short))
    assert (e.code, e.field) == (grpc.StatusCode.INVALID_ARGUMENT, "depth.depth_u16")
    step = pb.PackedPoints(data=b"\0" * 32, point_step=16, x_offset=0, y_offset=4, z_offset=13)
    assert refused(pb.UpdatePointCloudRequest(scene_id=scene, name="c", points=step)).field == "points.z_offset"

    points = to_sensor(ring())
    with pytest.raises(SublevelError) as e:
        client.update_point_cloud(scene, "c", points=points, voxel=5.0)
    assert e.value.field == "filter.voxel"
    with pytest.raises(SublevelError) as e:
        client.update_point_cloud(scene, "", points=points)
    assert e.value.field == "name"
    bare = client.create_scene("no robot")
    try:
        with pytest.raises(SublevelError) as e:
            client.update_point_cloud(bare, "c", points=points, self_filter=True)
        assert e.value.code == grpc.StatusCode.FAILED_PRECONDITION
    finally:
        client.delete_scene(bare)
    with pytest.raises(SublevelError) as e:
        client.remove_point_cloud(scene, "nothing")
    assert e.value.code == grpc.StatusCode.NOT_FOUND


def test_the_self_filter_drops_the_arm(client, cell):
    _, scene = cell
    client.set_joint_positions(scene, {"j": 0.0})
    # Points 3 mm off the arm's ball (their balls touch it) and a few far away.
    a = np.linspace(0.0, 2.0 * math.pi, 40, endpoint=False)
    on_arm = arm_ball(0.0) + (RA + 0.003) * np.stack([np.cos(a), np.sin(a), np.zeros(40)], axis=1)
    far = np.array([[-1.0, 0.0, 0.0], [-1.0, 0.5, 0.0], [0.0, -1.0, 0.3]])
    points = to_sensor(np.vstack([on_arm, far]))
    r = client.update_point_cloud(scene, "arm view", points=points, sensor_pose=SENSOR, voxel=0.0, self_filter=True)
    assert (r.counts.robot, r.counts.kept) == (40, 3)
    assert not client.check_configurations(None, [[0.0]], scene=scene).collides[0]
    client.remove_point_cloud(scene, "arm view")


def blob(n=200, radius=0.05, j=1.0):
    """``n`` points on a sphere of ``radius`` about the arm's ball at ``j`` (a Fibonacci sphere)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    a = np.arange(n) * 2.399963229728653
    s = np.sqrt(1.0 - z * z)
    return arm_ball(j) + radius * np.stack([s * np.cos(a), s * np.sin(a), z], axis=1)


def test_the_bodies_model_contains_the_points_balls(client, cell):
    _, scene = cell
    inliers = blob()
    lone = np.array([[-0.8, 0.0, 0.3], [0.0, -0.9, -0.4]])
    js = np.linspace(-3.0, 3.0, 61)
    client.update_point_cloud(scene, "camera", points=to_sensor(inliers), sensor_pose=SENSOR, voxel=0.0)
    points = client.check_configurations(None, js[:, None], scene=scene, distance=True)

    frame = to_sensor(np.vstack([inliers, lone]))
    r = client.update_point_cloud(scene, "camera", points=frame, sensor_pose=SENSOR, voxel=0.0, model="bodies")
    assert r.bodies is not None
    assert (r.bodies.clusters, r.bodies.outliers, r.bodies.fitted) == (1, 2, 1)
    bodies = client.check_configurations(None, js[:, None], scene=scene, distance=True)
    assert bodies.scene_version == r.scene_version
    for k, j in enumerate(js):
        # The body contains every inlier's ball: never free where they collide, never farther.
        if points.collides[k]:
            assert bodies.collides[k], j
        elif not bodies.collides[k]:
            assert bodies.distance[k] <= points.distance[k] + 1e-9, j
            assert bodies.world_object[k] == "camera"
    assert np.sum(points.collides) >= 3

    again = client.update_point_cloud(scene, "camera", points=frame, sensor_pose=SENSOR, voxel=0.0, model="bodies")
    assert (again.bodies.reused, again.bodies.fitted) == (1, 0)
    (info,) = client.get_scene(scene).point_clouds
    assert (info.model, info.bodies, info.points) == ("bodies", 1, 202)
    with pytest.raises(ValueError, match="body_degree"):
        client.update_point_cloud(scene, "camera", points=frame, model="bodies", body_degree=6)
    with pytest.raises(ValueError, match="model"):
        client.update_point_cloud(scene, "camera", points=frame, model="octree")
    client.remove_point_cloud(scene, "camera")
