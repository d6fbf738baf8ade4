"""`Client.plan(..., trajectory=True)` against a real server: a MotionBenchMaker Panda problem (box
scene 1, request 1) planned and timed within the Panda's MoveIt ``joint_limits.yaml``
(data/robots/panda), the trajectory checked independently of the server: it starts and ends at rest
on the path's ends, its 1 ms samples keep within the file's limits (read here with PyYAML) to 1e-6
relative, its positions agree with its velocities, every sample is free by
``check_configurations`` on the meshes, blending is no slower than stopping at every waypoint, and
bad settings are refused naming the field (docs/planning.md, "Timed trajectories")."""

from pathlib import Path

import grpc
import numpy as np
import pytest

from sublevel_client import JointTrajectory, SublevelError

REPO = Path(__file__).resolve().parents[3]
PANDA = REPO / "data" / "robots" / "panda"
MBM = REPO / "data" / "robots" / "mbm_panda"
SCENE = MBM / "scenes" / "box" / "scene0001.yaml"
REQUEST = MBM / "requests" / "box" / "request0001.yaml"
LIMITS = PANDA / "joint_limits.yaml"
JOINTS = [f"panda_joint{i}" for i in range(1, 8)]
TIMEOUT = 30.0
SEED = 7


def file_limits():
    """The velocity and acceleration limits of the arm's joints in joint_limits.yaml, by PyYAML."""
    yaml = pytest.importorskip("yaml")
    joints = yaml.safe_load(LIMITS.read_text())["robot_description_planning"]["joint_limits"]
    return (np.array([joints[j]["max_velocity"] for j in JOINTS]),
            np.array([joints[j]["max_acceleration"] for j in JOINTS]))


@pytest.fixture(scope="module")
def panda(client):
    info = client.upload_robot(PANDA / "panda.robot.json")
    yield info
    client.delete_robot(info.robot_id)


@pytest.fixture(scope="module")
def box(client):
    scene = client.import_scene(SCENE, name="box scene0001 (trajectory)").scene_id
    yield scene
    client.delete_scene(scene)


@pytest.fixture(scope="module")
def timed(client, panda, box):
    return client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, timeout=TIMEOUT, seed=SEED,
                       trajectory=True, sample_dt=0.001, joint_limits=LIMITS)


def test_a_plan_answers_a_trajectory_at_rest_on_its_ends_within_the_limits(timed):
    r = timed
    assert r.solved and r.certified, r
    tr = r.trajectory
    assert isinstance(tr, JointTrajectory)
    assert tr.joint_names == r.joint_names == JOINTS
    assert tr.certified
    v, a = file_limits()
    np.testing.assert_array_equal(tr.max_velocity, v)
    np.testing.assert_array_equal(tr.max_acceleration, a)
    # The file sets the finger joints' limits; this robot's fingers are fixed: said and skipped.
    assert any("panda_finger_joint1: not a moving joint" in w for w in r.warnings), r.warnings
    p = tr.t.shape[0]
    assert tr.q.shape == tr.qd.shape == tr.qdd.shape == (p, 7)
    assert tr.t[0] == 0.0 and tr.t[-1] == pytest.approx(tr.duration, abs=0.0)
    assert np.all(np.diff(tr.t) > 0) and np.all(np.diff(tr.t) <= 0.001 + 1e-12)
    np.testing.assert_array_equal(tr.q[0], r.path[0])
    np.testing.assert_array_equal(tr.q[-1], r.path[-1])
    assert not tr.qd[0].any() and not tr.qd[-1].any()
    assert np.all(np.abs(tr.qd) <= v * (1 + 1e-6))
    assert np.all(np.abs(tr.qdd) <= a * (1 + 1e-6))
    # Positions agree with velocities: the trapezoid rule's error is within a·dt².
    dt = np.diff(tr.t)[:, None]
    moved = np.diff(tr.q, axis=0)
    predicted = (tr.qd[1:] + tr.qd[:-1]) / 2 * dt
    assert np.all(np.abs(moved - predicted) <= a * dt * dt)
    assert tr.blends + tr.stops >= 1 or r.waypoints == 2
    assert 0.0 < tr.seconds < r.timing["total"]


def test_every_millisecond_sample_is_free_on_the_meshes(client, panda, box, timed):
    tr = timed.trajectory
    answer = client.check_configurations(panda.robot_id, tr.q, scene=box)
    assert not np.any(answer.collides), np.flatnonzero(answer.collides)[:5]


def test_blending_is_no_slower_than_stopping_at_every_waypoint(client, panda, box, timed):
    stopped = client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, timeout=TIMEOUT, seed=SEED,
                          trajectory=True, max_deviation=0.0, joint_limits=LIMITS)
    np.testing.assert_array_equal(stopped.path, timed.path)
    assert stopped.trajectory.blends == 0
    assert stopped.trajectory.stops == timed.waypoints - 2
    assert timed.trajectory.duration <= stopped.trajectory.duration


def test_scaling_slows_the_trajectory_and_bad_settings_name_their_field(client, panda, box, timed):
    half = client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, timeout=TIMEOUT, seed=SEED,
                       trajectory=True, joint_limits=LIMITS, velocity_scaling=0.5, acceleration_scaling=0.25)
    # Halved velocities and quartered accelerations: the same motion at half the speed, twice as long.
    assert half.trajectory.duration == pytest.approx(2 * timed.trajectory.duration, rel=1e-3)
    np.testing.assert_allclose(half.trajectory.max_velocity, timed.trajectory.max_velocity / 2)
    with pytest.raises(ValueError, match="velocity_scaling"):
        client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, trajectory=True, velocity_scaling=1.5)
    with pytest.raises(SublevelError) as e:
        client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, trajectory=True,
                    max_velocity={"no_such_joint": 1.0})
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and "trajectory.max_velocity[no_such_joint]" in str(e.value)
    with pytest.raises(SublevelError) as e:
        client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, trajectory=True,
                    joint_limits="joint_limits:\n  panda_joint1:\n    has_velocity_limits: true\n")
    assert "trajectory.joint_limits_yaml.joint_limits.panda_joint1.max_velocity" in str(e.value)
    with pytest.raises(SublevelError) as e:
        client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, trajectory=True, sample_dt=1e-9)
    assert "sample_dt" in str(e.value)


def test_a_robot_without_acceleration_limits_takes_the_defaults_and_says_so(client, panda, box):
    r = client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, timeout=TIMEOUT, seed=SEED,
                    trajectory=True)
    # The URDF gives velocity limits; no acceleration limit anywhere: 1 rad/s² each, said.
    np.testing.assert_array_equal(r.trajectory.max_acceleration, np.ones(7))
    assert sum("no acceleration limit" in w for w in r.warnings) == 7, r.warnings
    assert not any("no velocity limit" in w for w in r.warnings)


READY = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])


def test_a_straight_move_of_one_joint_takes_the_closed_form_time(client, panda):
    # Joint 1 moves 1 rad with v = 2.175 rad/s and a = 3.75 rad/s²: it never reaches v
    # (1 < v²/a = 1.2615), so the time-optimal motion accelerates half way and brakes the other:
    # t = 2·sqrt(L / a).
    end = READY.copy()
    end[0] += 1.0
    tr = client.time_trajectory(panda.robot_id, [READY, end], joint_limits=LIMITS, sample_dt=0.001)
    assert tr.duration == pytest.approx(2 * np.sqrt(1.0 / 3.75), rel=1e-6)
    assert tr.certified and tr.blends == 0 and tr.stops == 0
    assert np.max(np.abs(tr.qd[:, 0])) == pytest.approx(np.sqrt(3.75 * 1.0), rel=1e-3)
    np.testing.assert_array_equal(tr.q[:, 1:], np.tile(READY[1:], (tr.q.shape[0], 1)))
    # A coasting move: 3 rad at most 2.175 rad/s reaches it: t = L / v + v / a (the stations are
    # 0.01 rad apart and the switch to coasting falls between two: within 1e-5).
    far = READY.copy()
    far[0] = -1.5
    tr = client.time_trajectory(panda.robot_id, [far, far + np.eye(7)[0] * 3.0], joint_limits=LIMITS)
    assert tr.duration == pytest.approx(3.0 / 2.175 + 2.175 / 3.75, rel=1e-5)


def test_another_planners_path_is_timed_as_the_plan_times_it(client, panda, box, timed):
    tr = client.time_trajectory(panda.robot_id, timed.path, scene=box, joint_limits=LIMITS, sample_dt=0.001)
    assert tr.duration == pytest.approx(timed.trajectory.duration, rel=1e-9)
    np.testing.assert_allclose(tr.q, timed.trajectory.q, atol=1e-12)
    assert not any("no velocity" in w or "no acceleration" in w for w in tr.warnings)


def test_a_path_through_an_obstacle_names_its_first_edge_that_is_not_free(client, panda, box, timed):
    import csv

    with open(MBM / "labels_obj.csv", newline="") as f:
        hit = next(np.array([float(r[f"q{i}"]) for i in range(1, 8)]) for r in csv.DictReader(f)
                   if r["scenario"] == "box" and r["scene"] == "1" and r["collides_world"] == "1")
    start = timed.path[0]
    with pytest.raises(SublevelError) as e:
        client.time_trajectory(panda.robot_id, [start, start, hit], scene=box)
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
    # Edges are counted in the path as sent, its repeated waypoint included.
    assert "`path`" in str(e.value) and "edge 1 (waypoint 1 to 2)" in str(e.value), str(e.value)
    with pytest.raises(SublevelError) as e:
        client.time_trajectory(panda.robot_id, [start, start])
    assert "path" in str(e.value) and "two distinct" in str(e.value)
    with pytest.raises(ValueError, match="path"):
        client.time_trajectory(panda.robot_id, [start[:3], start[:3]])
