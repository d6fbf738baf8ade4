"""A robot placed in a scene (SetSceneRobot and friends) against closed forms: a one-joint arm
whose link holds a ball, and a ball obstacle. Checks naming no robot use the scene's robot (its
base, attached objects, link padding and joint positions), CheckScene checks it at the scene's
joint positions, and a planner stream checks configurations and motions on its private view."""

import math
from pathlib import Path

import grpc
import numpy as np
import pytest

from sublevel_client import ConfigurationColumns, MotionColumns, Pose, SceneRobot, SublevelError

# The arm: a revolute joint `j` about z at the base; link `arm` holds a ball of radius RA at
# (L, 0, 0) of its frame. The obstacle: a ball of radius RO at O.
L, RA, RO = 0.5, 0.1, 0.2
O = np.array([0.5, 1.0, 0.0])
HALF_PI = math.pi / 2
ARM = Path(__file__).resolve().parents[3] / "tests" / "data" / "arm.robot.json"
C45 = L * math.cos(math.pi / 4)  # the obstacle's private pose on a stream: on the arm ball's circle at 45°


def arm_file() -> bytes:
    """The arm's robot file (the repository's tests/data/arm.robot.json)."""
    return ARM.read_bytes()


def ball_distance(j, at, radius, obstacle=O, base=np.zeros(3)):
    """Distance (m) from a ball of ``radius`` at ``at`` (x, y, z) in the arm's frame, the joint at
    ``j`` rad, to the obstacle ball."""
    c, s = math.cos(j), math.sin(j)
    center = base + np.array([c * at[0] - s * at[1], s * at[0] + c * at[1], at[2]])
    return float(np.linalg.norm(np.asarray(obstacle) - center)) - radius - RO


def arm_distance(j, obstacle=O, base=np.zeros(3)):
    return ball_distance(j, (L, 0.0, 0.0), RA, obstacle, base)


@pytest.fixture(scope="module")
def cell(client):
    """(robot id, scene id, obstacle instance id): the arm uploaded, a scene with the obstacle."""
    robot = client.upload_robot(arm_file())
    scene = client.create_scene("arm cell")
    obstacle = client.add_instance(scene, client.upload_primitive("sphere", radius=RO), Pose(t=O))
    yield robot.robot_id, scene, obstacle
    client.delete_scene(scene)
    client.delete_robot(robot.robot_id)


def test_closed_forms_check_the_scene_robot(client, cell):
    robot, scene, obstacle = cell
    placed = client.set_scene_robot(scene, robot)
    assert isinstance(placed, SceneRobot)
    assert (placed.robot_id, placed.base, placed.attached, placed.link_padding) == (robot, Pose(), [], {})
    assert placed.joint_positions == {"j": 0.0} and placed.joint_names == ["j"]
    assert client.get_scene(scene).robot == placed

    # j = 0: the balls' centers 1 m apart, 0.7 m between them; j = π/2: √0.5 − 0.3.
    assert abs(arm_distance(0.0) - 0.7) < 1e-12 and abs(arm_distance(HALF_PI) - (math.sqrt(0.5) - 0.3)) < 1e-12
    for who in (None, ""):
        r = client.check_configurations(who, [[0.0], [HALF_PI]], scene=scene, distance=True)
        assert isinstance(r, ConfigurationColumns) and r.joint_names == ["j"]
        np.testing.assert_allclose(r.distance, [0.7, math.sqrt(0.5) - 0.3], atol=1e-9)
        assert not r.collides.any() and r.robot_link == ["arm", "arm"] and r.world_object == [obstacle] * 2
    # One configuration as a (1,) array, with the joints named, and the distance's gradient:
    # d(j) = |c(j) − O| − 0.3 with c(j) = 0.5 (cos j, sin j): d'(0) = −0.5.
    r = client.check_configurations(None, [0.0], scene=scene, joint_names=["j"], gradient=True)
    assert abs(r.distance[0] - 0.7) < 1e-9
    np.testing.assert_allclose(r.gradient, [[-0.5]], atol=1e-9)
    np.testing.assert_allclose(r.witnesses[0], [[L, RA, 0.0], [0.5, 1.0 - RO, 0.0]], atol=1e-9)

    # The scene robot's base; a request's base replaces it.
    base = np.array([0.0, 0.2, 0.0])
    placed = client.set_scene_robot(scene, robot, base=Pose(t=base))
    assert placed.base == Pose(t=base)
    r = client.check_configurations(None, [[0.0], [HALF_PI]], scene=scene, distance=True)
    np.testing.assert_allclose(r.distance, [arm_distance(0.0, base=base), arm_distance(HALF_PI, base=base)], atol=1e-9)
    assert abs(r.distance[0] - 0.5) < 1e-9
    r = client.check_configurations(None, [0.0], scene=scene, distance=True, base=Pose())
    assert abs(r.distance[0] - 0.7) < 1e-9

    # Link padding: the scene's, replaced link by link by the request's; distances stay unpadded.
    client.set_scene_robot(scene, robot, link_padding={"arm": 0.7 + 1e-6})
    r = client.check_configurations(None, [0.0], scene=scene, distance=True)
    assert r.collides[0] and r.world[0]
    r = client.check_configurations(None, [0.0], scene=scene, distance=True, link_padding={"arm": 0.7 - 1e-6})
    assert not r.collides[0] and abs(r.distance[0] - 0.7) < 1e-9
    # A named robot is the bare robot: no scene padding.
    assert not client.check_configurations(robot, [0.0], scene=scene).collides[0]

    # Motions: the arc j: 0 → π/2 keeps the ball √1.25 − 0.5 − 0.3 m clear of the obstacle.
    client.set_scene_robot(scene, robot)
    m = client.check_motions(None, [0.0], [HALF_PI], scene=scene)
    assert isinstance(m, MotionColumns) and m.valid[0] and m.decided[0] and math.isnan(m.contact_t[0])
    # With the base where the obstacle sits on the ball's circle at 45°, the motion touches it
    # where the chord 2 · 0.5 · sin(|θ − π/4| / 2) falls to 0.3 m: at θ* = π/4 − 2 asin(0.3),
    # reported no later than t* = θ* / (π/2) and within the 1 mm tolerance of it (the ball's far
    # side moves at most 0.6 · π/2 m per unit of t).
    t_star = (math.pi / 4 - 2 * math.asin(0.3)) / HALF_PI
    m = client.check_motions(None, [0.0], [HALF_PI], scene=scene, joint_names=["j"], base=Pose(t=O - [C45, C45, 0.0]))
    assert not m.valid[0] and m.decided[0]
    assert t_star - 1e-3 / (0.6 * HALF_PI) - 1e-9 <= m.contact_t[0] <= t_star + 1e-12, (m.contact_t[0], t_star)
    assert (m.robot_link[0], m.other[0]) == ("arm", obstacle)
    # Stopping at the first collision: the ball at 45° touches the obstacle, so π/2 is not checked.
    q, at45 = [[0.0], [math.pi / 4], [HALF_PI]], Pose(t=O - [C45, C45, 0.0])
    r = client.check_configurations(None, q, scene=scene, base=at45, stop_at_first_collision=True)
    assert r.collides.tolist() == [False, True]
    assert client.check_configurations(None, q, scene=scene, base=at45).collides.tolist() == [False, True, False]


def test_attached_objects_move_with_their_link(client, cell):
    robot, scene, obstacle = cell
    client.set_scene_robot(scene, robot)
    # A ball of radius 0.05 at (0.8, 0, 0) on `arm`: at j = π/2 its center is at (0, 0.8, 0),
    # √0.29 m from the obstacle's, closer than the arm's own ball (√0.5 − 0.3).
    tool = {"link": "arm", "name": "tool", "kind": "sphere", "radius": 0.05, "origin": Pose(t=(0.8, 0.0, 0.0))}
    expected = math.sqrt(0.29) - 0.25
    assert abs(ball_distance(HALF_PI, (0.8, 0.0, 0.0), 0.05) - expected) < 1e-12
    assert expected < arm_distance(HALF_PI)
    placed = client.attach_object(scene, "arm", "tool", "sphere", radius=0.05, origin=Pose(t=(0.8, 0.0, 0.0)))
    assert placed.attached == [tool]
    assert client.get_scene(scene).robot.attached == [tool]
    r = client.check_configurations(None, [HALF_PI], scene=scene, distance=True)
    assert abs(r.distance[0] - expected) < 1e-9
    assert (r.robot_link[0], r.robot_geometry[0], r.world_object[0]) == ("arm", "tool", obstacle)
    n = (O - np.array([0.0, 0.8, 0.0])) / math.sqrt(0.29)
    np.testing.assert_allclose(r.witnesses[0, 0], np.array([0.0, 0.8, 0.0]) + 0.05 * n, atol=1e-9)
    # Naming the robot checks the bare robot.
    bare = client.check_configurations(robot, [HALF_PI], scene=scene, distance=True)
    assert abs(bare.distance[0] - arm_distance(HALF_PI)) < 1e-9
    # A request's objects add to the scene's: a box of side 0.1 at (1, −0.5, 0) of the link sits
    # at the obstacle's center (0.5, 1, 0) when j = π/2; at j = 0 it is more than √2.5 − 0.3 m
    # away, the tool ball √1.09 − 0.25 m, and the arm's ball, the closest, 0.7 m.
    extra = {"link": "arm", "name": "extra", "kind": "box", "size": (0.1, 0.1, 0.1), "origin": [1, 0, 0, 0, 1.0, -0.5, 0.0]}
    r = client.check_configurations(None, [HALF_PI], scene=scene, distance=True, attached=[extra])
    assert r.collides[0] and r.robot_geometry[0] == "extra"
    r = client.check_configurations(None, [0.0], scene=scene, distance=True, attached=[extra])
    assert not r.collides[0] and r.robot_geometry[0] == "arm" and abs(r.distance[0] - 0.7) < 1e-9
    assert ball_distance(0.0, (0.8, 0.0, 0.0), 0.05) > 0.7

    # Re-attaching from the SceneRobot's dict form, replacing by name; a second object; detaching.
    placed = client.attach_object(scene, **{**tool, "radius": 0.06})
    assert [a["radius"] for a in placed.attached] == [0.06]
    placed = client.attach_object(scene, "arm", "box", "box", size=(0.1, 0.2, 0.3))
    assert [a["name"] for a in placed.attached] == ["tool", "box"]
    assert placed.attached[1]["size"] == (0.1, 0.2, 0.3) and placed.attached[1]["origin"] == Pose()
    assert [a["name"] for a in client.detach_object(scene, "tool").attached] == ["box"]
    with pytest.raises(SublevelError) as e:
        client.detach_object(scene, "tool")
    assert e.value.code == grpc.StatusCode.NOT_FOUND
    # set_scene_robot takes the same dicts back.
    placed = client.set_scene_robot(scene, robot, attached=[tool])
    assert placed.attached == [tool]
    with pytest.raises(SublevelError) as e:
        client.attach_object(scene, "nope", "cup", "sphere", radius=0.05)
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and e.value.field == "attached.link"
    with pytest.raises(ValueError, match="`name`"):
        client.attach_object(scene, "arm", "", "sphere", radius=0.05)
    assert client.get_scene(scene).robot.attached == [tool]


def test_joint_positions_are_the_scene_state(client, cell):
    robot, scene, obstacle = cell
    placed = client.set_scene_robot(scene, robot, joint_positions={"j": 0.0})
    check = client.check_scene(scene)
    assert check.robot is not None and len(check.robot) == 1
    assert abs(check.robot.distance[0] - 0.7) < 1e-9 and not check.robot.collides[0]

    placed = client.set_joint_positions(scene, {"j": HALF_PI})
    assert placed.joint_positions == {"j": HALF_PI}
    sc = client.get_scene(scene)
    assert sc.robot.joint_positions == {"j": HALF_PI} and sc.joint_positions["j"] == HALF_PI
    assert abs(client.check_scene(scene).robot.distance[0] - (math.sqrt(0.5) - 0.3)) < 1e-9
    # The check's margin pads the robot.
    assert client.check_scene(scene, margin=math.sqrt(0.5) - 0.3 + 1e-6).robot.collides[0]
    assert not client.check_scene(scene, margin=math.sqrt(0.5) - 0.3 - 1e-6).robot.collides[0]
    # CheckScene's poses move the obstacle for that check: 0.3 m further along y.
    moved = client.check_scene(scene, poses={obstacle: Pose(t=O + [0.0, 0.3, 0.0])})
    assert abs(moved.robot.distance[0] - arm_distance(HALF_PI, obstacle=O + [0.0, 0.3, 0.0])) < 1e-9

    # An unknown joint: refused whole, naming it; nothing changes.
    before = client.get_scene(scene)
    with pytest.raises(SublevelError) as e:
        client.set_joint_positions(scene, {"k": 1.0, "j": 0.3})
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and e.value.field == "joint_positions.joint_names[0]"
    assert client.get_scene(scene) == before
    with pytest.raises(SublevelError) as e:
        client.set_scene_robot(scene, robot, base=Pose(t=(1, 2, 3)), joint_positions={"k": 1.0})
    assert e.value.field == "joint_positions.joint_names[0]"
    assert client.get_scene(scene) == before
    with pytest.raises(ValueError, match=r"`positions\[j\]`"):
        client.set_joint_positions(scene, {"j": float("nan")})
    with pytest.raises(ValueError, match="`joint_positions`"):
        client.set_scene_robot(scene, robot, joint_positions=[0.3])
    assert client.get_scene(scene) == before

    # Without a robot: no robot check, no robot for checks naming none; the joint positions stay.
    assert client.clear_scene_robot(scene) is True
    assert client.clear_scene_robot(scene) is False
    sc = client.get_scene(scene)
    assert sc.robot is None and sc.joint_positions == {"j": HALF_PI}
    assert client.check_scene(scene).robot is None
    for names in (None, ["j"]):  # looked up by the client, or refused by the server: the same error
        with pytest.raises(SublevelError) as e:
            client.check_configurations(None, [0.0], scene=scene, joint_names=names)
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and e.value.field == "robot_id", names
    with pytest.raises(SublevelError) as e:
        client.set_joint_positions(scene, {"j": 0.0})
    assert e.value.code == grpc.StatusCode.FAILED_PRECONDITION
    with pytest.raises(ValueError, match="`robot`"):
        client.check_configurations(None, [0.0])
    with pytest.raises(ValueError, match="`robot`"):
        client.check_motions(None, [0.0], [1.0])

    # Placed again, the robot takes the scene's joint positions.
    assert client.set_scene_robot(scene, robot).joint_positions == {"j": HALF_PI}
    with pytest.raises(ValueError, match=r"`q`.*\(configurations, 1\).*robot of scene"):
        client.check_configurations(None, [[0.0, 1.0]], scene=scene)
    client.set_joint_positions(scene, {"j": 0.0})


def test_a_stream_checks_the_scene_robot_on_its_view(client, cell):
    robot, scene, obstacle = cell
    client.set_scene_robot(scene, robot, joint_positions={"j": 0.0})
    private = Pose(t=(C45, C45, 0.0))
    expected = 2 * L * math.sin(math.pi / 8) - (RA + RO)
    assert abs(arm_distance(0.0, obstacle=[C45, C45, 0.0]) - expected) < 1e-12
    t_star = (math.pi / 4 - 2 * math.asin(0.3)) / HALF_PI
    with client.stream(scene) as s:
        r = s.check_configurations([[0.0], [HALF_PI]], distance=True)
        assert isinstance(r, ConfigurationColumns)
        np.testing.assert_allclose(r.distance, [0.7, math.sqrt(0.5) - 0.3], atol=1e-9)
        r = s.check_configurations([0.0], ["j"], gradient=True)
        np.testing.assert_allclose(r.gradient, [[-0.5]], atol=1e-9)

        # The stream moves the obstacle onto the ball's circle at 45°, privately.
        r = s.check_configurations([0.0], distance=True, poses={obstacle: private})
        assert abs(r.distance[0] - expected) < 1e-9, (r.distance[0], expected)
        unary = client.check_configurations(None, [0.0], scene=scene, distance=True)
        assert abs(unary.distance[0] - 0.7) < 1e-9
        # The view keeps the pose: j: 0 → π/2 touches the obstacle where the chord falls to 0.3 m,
        # reported no later than t* and within the 1 mm tolerance of it (the ball's far side moves
        # at most 0.6 · π/2 m per unit of t).
        m = s.check_motions([0.0], [HALF_PI])
        assert isinstance(m, MotionColumns) and not m.valid[0] and m.decided[0]
        assert t_star - 1e-3 / (0.6 * HALF_PI) - 1e-9 <= m.contact_t[0] <= t_star + 1e-12, (m.contact_t[0], t_star)
        assert (m.robot_link[0], m.other[0]) == ("arm", obstacle)
        np.testing.assert_allclose(m.contact_configuration[0], [m.contact_t[0] * HALF_PI], atol=1e-12)
        assert client.check_motions(None, [0.0], [HALF_PI], scene=scene).valid[0]
        # Poses sent with a motion request: the obstacle back home, the motion is free.
        m = s.check_motions([0.0], [HALF_PI], poses={obstacle: Pose(t=O)}, robot=robot)
        assert m.valid[0]
        # Client-side errors leave the stream open.
        with pytest.raises(ValueError, match="`q`"):
            s.check_configurations([[0.0, 1.0]])
        assert abs(s.check_configurations([0.0], distance=True).distance[0] - 0.7) < 1e-9
    assert abs(client.check_scene(scene).robot.distance[0] - 0.7) < 1e-9

    # The server's refusals name their field, prefixed; they end the stream.
    with client.stream(scene) as s:
        with pytest.raises(SublevelError) as e:
            s.check_configurations([0.0], ["k"])
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert e.value.field == "robot_states.configurations.joint_names[0]"
        with pytest.raises(SublevelError):
            s.check_configurations([0.0])
    with client.stream(scene) as s:
        with pytest.raises(SublevelError) as e:
            s.check_motions([0.0], [1.0], ["k"])
        assert e.value.field == "robot_motions.start.joint_names[0]"
