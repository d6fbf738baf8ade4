"""`Client.plan` against a real server: a MotionBenchMaker Panda problem (box scene 1, request 1:
data/robots/mbm_panda) planned from its MotionPlanRequest text and from typed ends, the path checked
independently of the planner — its ends against the request file (read here with PyYAML), its length
against its rows, every edge by `check_motions` (conservative advancement) and by
`check_configurations` sampled 2000 times per unit of joint distance — and the statuses and errors
of the call (docs/planning.md)."""

import csv
import json
import math
from pathlib import Path

import grpc
import numpy as np
import pytest

from sublevel_client import Client, PlanResult, SublevelError

REPO = Path(__file__).resolve().parents[3]
PANDA = REPO / "data" / "robots" / "panda"
MBM = REPO / "data" / "robots" / "mbm_panda"
SCENE = MBM / "scenes" / "box" / "scene0001.yaml"
REQUEST = MBM / "requests" / "box" / "request0001.yaml"
JOINTS = [f"panda_joint{i}" for i in range(1, 8)]

TIMEOUT = 30.0  # seconds per plan: the debug server solves this problem in about one
SEED = 7
DENSITY = 2000  # configurations per unit of joint distance on the dense re-check of each edge
# The plan keeps an edge proven free at the contact tolerance (1 mm) or at a hundredth of it
# (docs/planning.md, crates/plan/src/certify.rs): the edges are re-checked at the latter.
CERTIFIED_TOLERANCE = 1e-3 / 100


def request_ends():
    """The request's start (its first 7 joint positions, the fingers left out) and its goal (the
    joint constraints by name), read with PyYAML."""
    yaml = pytest.importorskip("yaml")
    req = yaml.safe_load(REQUEST.read_text())
    js = req["start_state"]["joint_state"]
    start_by_name = dict(zip(js["name"], js["position"]))
    goal_by_name = {c["joint_name"]: c["position"] for c in req["goal_constraints"][0]["joint_constraints"]}
    assert sorted(goal_by_name) == JOINTS
    return np.array([start_by_name[j] for j in JOINTS], dtype=float), np.array([goal_by_name[j] for j in JOINTS])


def colliding_configuration():
    """A configuration of box scene 1 that collides with the world by the mesh labels."""
    with open(MBM / "labels_obj.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["scenario"] == "box" and r["scene"] == "1" and r["collides_world"] == "1":
                return np.array([float(r[f"q{i}"]) for i in range(1, 8)])
    raise AssertionError("no colliding label in box scene 1")


@pytest.fixture(scope="module")
def panda(client):
    info = client.upload_robot(PANDA / "panda.robot.json")
    yield info
    client.delete_robot(info.robot_id)


@pytest.fixture(scope="module")
def box(client):
    scene = client.import_scene(SCENE, name="box scene0001 (plan)").scene_id
    yield scene
    client.delete_scene(scene)


@pytest.fixture(scope="module")
def solved(client, panda, box):
    """The request planned from its text (the file's path)."""
    return client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, timeout=TIMEOUT, seed=SEED)


def test_a_motionbenchmaker_request_is_solved_with_a_certified_path(client, panda, box, solved):
    start, goal = request_ends()
    r = solved
    assert isinstance(r, PlanResult)
    assert r.status == "solved" and r.solved and r.message == "", r
    assert r.certified and r.unproven_edges.shape == (0,) and r.unproven_edges.dtype.kind == "i"
    assert r.joint_names == JOINTS
    assert r.path.dtype == float and r.path.ndim == 2 and r.path.shape[1] == 7 and r.path.shape[0] >= 2
    assert r.waypoints == r.path.shape[0]
    # From the request's start to its goal, exactly as the file writes them.
    np.testing.assert_array_equal(r.path[0], start)
    np.testing.assert_array_equal(r.path[-1], goal)
    np.testing.assert_array_equal(r.goal, goal)
    # Inside the URDF's limits, and the length the rows make (no continuous joint on the Panda).
    assert np.all(r.path >= panda.lower) and np.all(r.path <= panda.upper)
    edges = np.linalg.norm(np.diff(r.path, axis=0), axis=1)
    assert r.length == pytest.approx(edges.sum(), rel=1e-12)
    assert r.length >= np.linalg.norm(goal - start) - 1e-12
    # The figures: every stage timed within the call, the checks counted.
    assert set(r.timing) == {"goals", "search", "simplify", "certify", "total"}
    assert all(v >= 0.0 for v in r.timing.values())
    assert r.timing["total"] >= r.timing["search"] + r.timing["simplify"] + r.timing["certify"]
    assert r.timing["total"] < TIMEOUT
    assert r.timing["search"] > 0.0 and r.timing["certify"] > 0.0
    assert r.states_checked > 0 and r.edges_checked > 0 and r.nodes >= 2
    assert r.edges_certified >= r.waypoints - 1 and r.advancement_steps >= r.edges_certified
    assert r.repaired >= 0


def test_typed_ends_give_the_same_path(client, panda, box, solved):
    start, goal = request_ends()
    typed = client.plan(panda.robot_id, scene=box, start=start, goal=goal, timeout=TIMEOUT, seed=SEED)
    assert typed.status == "solved"
    np.testing.assert_array_equal(typed.path, solved.path)
    assert typed.length == solved.length
    # The same request as YAML text, as JSON text, by named joints in another order, and planned
    # for the scene's robot: the same path.
    text = REQUEST.read_text()
    assert client.plan(panda.robot_id, scene=box, motion_plan_request=text, timeout=TIMEOUT, seed=SEED).path.tolist() \
        == solved.path.tolist()
    yaml = pytest.importorskip("yaml")
    as_json = json.dumps(yaml.safe_load(text))
    assert as_json.startswith("{")
    assert client.plan(panda.robot_id, scene=box, motion_plan_request=as_json, timeout=TIMEOUT, seed=SEED).path.tolist() \
        == solved.path.tolist()
    order = JOINTS[::-1]
    named = client.plan(panda.robot_id, scene=box, start=start[::-1], goal=goal[::-1], joint_names=order,
                        timeout=TIMEOUT, seed=SEED)
    np.testing.assert_array_equal(named.path, solved.path)  # answered in the robot's joint order
    scene = client.import_scene(SCENE, name="box scene0001 (plan, scene robot)").scene_id
    try:
        client.set_scene_robot(scene, panda.robot_id)
        mine = client.plan(None, scene=scene, motion_plan_request=REQUEST, timeout=TIMEOUT, seed=SEED)
        np.testing.assert_array_equal(mine.path, solved.path)
        mine = client.plan(None, scene=scene, start=start, goal=goal, timeout=TIMEOUT, seed=SEED)
        np.testing.assert_array_equal(mine.path, solved.path)
    finally:
        client.delete_scene(scene)


def test_every_edge_is_free_by_advancement_and_by_dense_sampling(client, panda, box, solved):
    p = solved.path
    motions = client.check_motions(panda.robot_id, p[:-1], p[1:], scene=box, tolerance=CERTIFIED_TOLERANCE)
    assert motions.valid.all() and motions.decided.all(), motions
    assert np.isnan(motions.contact_t).all()
    # Each edge sampled at DENSITY configurations per unit of joint distance, ends included.
    samples = []
    for a, b in zip(p[:-1], p[1:]):
        k = max(1, math.ceil(np.linalg.norm(b - a) * DENSITY))
        samples.append(a + (np.arange(k + 1) / k)[:, None] * (b - a))
    q = np.vstack(samples)
    assert len(q) >= solved.length * DENSITY
    checked = client.check_configurations(panda.robot_id, q, scene=box)
    assert len(checked) == len(q)
    assert not checked.collides.any(), np.flatnonzero(checked.collides)[:10]


def test_goal_regions_and_statuses(client, panda, box):
    start, goal = request_ends()
    # A joint region: joint 1 within [0.40, 0.50], the others at the start's values.
    r = client.plan(panda.robot_id, scene=box, start=start, goal_joints={"panda_joint1": (0.45, 0.05, 0.05)},
                    timeout=TIMEOUT, seed=SEED)
    assert r.status == "solved", r
    assert 0.40 <= r.goal[0] <= 0.50
    np.testing.assert_array_equal(r.goal[1:], start[1:])
    np.testing.assert_array_equal(r.path[-1], r.goal)
    # A start the mesh labels call colliding: no path, the pair named.
    hit = colliding_configuration()
    r = client.plan(panda.robot_id, scene=box, start=hit, goal=goal, timeout=TIMEOUT)
    assert r.status == "start_in_collision" and not r.solved
    assert r.path.shape == (0, 7) and r.goal is None and not r.certified and r.length == 0.0
    assert "collides with" in r.message and "panda_" in r.message, r.message
    # The same configuration as the only goal.
    r = client.plan(panda.robot_id, scene=box, start=start, goal=hit, timeout=TIMEOUT)
    assert r.status == "goal_in_collision" and r.path.shape == (0, 7) and "collides with" in r.message
    # A pose 5 m from the Panda's base: no inverse kinematics solution.
    far = {"link": "panda_hand", "pose": [1, 0, 0, 0, 5.0, 0.0, 0.5], "position_tolerance": 0.01}
    r = client.plan(panda.robot_id, scene=box, start=start, goal_pose=far, timeout=5.0)
    assert r.status == "goal_unreachable" and r.path.shape == (0, 7), r
    assert "inverse kinematics" in r.message
    # A plan with too little time ends timed out, with no path.
    r = client.plan(panda.robot_id, scene=box, motion_plan_request=REQUEST, timeout=1e-4)
    assert r.status == "timed_out" and r.path.shape == (0, 7) and r.goal is None and not r.certified


def test_server_refusals_name_the_field(client, panda, box):
    start, goal = request_ends()
    outside = start.copy()
    outside[1] = panda.lower[1] - 0.5
    cases = [
        (dict(start=outside, goal=goal), "start.values[1]", "outside"),
        (dict(start=start, goal=goal, joint_names=JOINTS[:6] + ["panda_joint_nope"]),
         "start.joint_names[6]", "panda_joint_nope"),
        (dict(start=start, goal_pose={"link": "panda_nope", "pose": np.eye(4)}), "goal_pose.link", "panda_nope"),
        (dict(start=start, goal_joints={"panda_joint_nope": 0.0}), "goal_joint_constraints[0].joint_name",
         "panda_joint_nope"),
        (dict(motion_plan_request="start_state: {joint_state: {name: [panda_joint2], position: [9.0]}}\n"
                                  "goal_constraints: [{joint_constraints: [{joint_name: panda_joint1, position: 0}]}]\n"),
         "motion_plan_request_yaml.start_state[1]", "outside"),
    ]
    for kwargs, field, word in cases:
        with pytest.raises(SublevelError) as e:
            client.plan(panda.robot_id, scene=box, **kwargs)
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT, e.value
        assert e.value.field == field, e.value
        assert word in e.value.message, e.value
    with pytest.raises(SublevelError) as e:
        client.plan("r-does-not-exist", scene=box, start=start, goal=goal, joint_names=JOINTS)
    assert e.value.code == grpc.StatusCode.NOT_FOUND
    with pytest.raises(SublevelError) as e:
        client.plan(panda.robot_id, scene="s-does-not-exist", motion_plan_request=REQUEST)
    assert e.value.code == grpc.StatusCode.NOT_FOUND


def test_a_start_just_past_a_limit_is_moved_onto_it_and_said(client, panda):
    # MoveIt's FixStartStateBounds: a start value up to 0.05 rad past its limit is planned from the
    # limit, and the answer says so naming the value; farther, or past a smaller bound error, it
    # is refused naming it. No scene: self-collision only.
    start, goal = request_ends()
    past = start.copy()
    past[0] = panda.upper[0] + 0.03
    r = client.plan(panda.robot_id, start=past, goal=goal, joint_names=JOINTS, timeout=TIMEOUT, seed=SEED)
    assert r.solved, r
    assert r.path[0][0] == panda.upper[0]
    np.testing.assert_array_equal(r.path[0][1:], start[1:])
    assert len(r.warnings) == 1 and r.warnings[0].startswith("start.values[0]: joint `panda_joint1`"), r.warnings
    with pytest.raises(SublevelError) as e:
        client.plan(panda.robot_id, start=past, goal=goal, joint_names=JOINTS, timeout=TIMEOUT,
                    start_state_max_bounds_error=0.01)
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and e.value.field == "start.values[0]", e.value
    r = client.plan(panda.robot_id, start=start, goal=goal, joint_names=JOINTS, timeout=TIMEOUT, seed=SEED)
    assert r.solved and r.warnings == [], r
    assert r.planning_joints == JOINTS


def test_a_plan_moves_only_its_planning_joints(client, panda):
    # The goal names two joints: the other five stay at the start's values on every waypoint. No
    # scene: self-collision only.
    start, goal = request_ends()
    r = client.plan(panda.robot_id, start=start, joint_names=JOINTS,
                    goal_joints={"panda_joint1": goal[0], "panda_joint4": goal[3]}, timeout=TIMEOUT, seed=SEED)
    assert r.solved, r
    assert r.planning_joints == ["panda_joint1", "panda_joint4"]
    held = [k for k in range(7) if k not in (0, 3)]
    np.testing.assert_array_equal(r.path[:, held], np.tile(start[held], (r.waypoints, 1)))
    assert r.path[-1][0] == goal[0] and r.path[-1][3] == goal[3]
    with pytest.raises(SublevelError) as e:
        client.plan(panda.robot_id, start=start, goal=goal, joint_names=JOINTS, planning_joints=["panda_joint1"],
                    timeout=TIMEOUT)
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and e.value.field == "planning_joints", e.value


def test_bad_arguments_raise_before_sending():
    # A client on an address no server listens on: a ValueError, not UNAVAILABLE, shows that
    # nothing was sent (the joint names given, so that no robot summary is fetched either).
    start, goal = request_ends()
    offline = Client("127.0.0.1:1", timeout=2.0)
    rid = "r-any"
    ok = dict(scene="s-x", start=start, goal=goal, joint_names=JOINTS)
    bad = [
        (dict(ok, start=start[:6]), r"`start`.*\(configurations, 7\)"),
        (dict(ok, start=np.vstack([start, start])), r"`start`: expected one configuration"),
        (dict(ok, goal=np.where(np.arange(7) == 3, np.nan, goal)), r"`goal`.*not finite"),
        (dict(ok, goal=[goal, goal[:6]]), r"`goal`"),
        (dict(ok, goal=None), r"`goal`: required"),
        (dict(ok, goal_joints={"panda_joint1": 0.1}), r"`goal_joints`: give one kind of goal"),
        (dict(ok, goal=None, goal_pose={"link": "panda_hand", "pose": [1, 0, 0]}), r"`goal_pose.pose`"),
        (dict(ok, goal=None, goal_pose={"pose": np.eye(4)}), r"`goal_pose.link`"),
        (dict(ok, goal=None, goal_pose={"link": "panda_hand", "pose": np.eye(4), "tol": 1}), r"`goal_pose`: unknown"),
        (dict(ok, goal=None, goal_joints={"panda_joint1": (0.1, -0.1, 0.1)}), r"`goal_joints\[panda_joint1\]`"),
        (dict(ok, goal=None, goal_joints={"panda_joint1": math.inf}), r"`goal_joints\[panda_joint1\]`"),
        (dict(ok, motion_plan_request=REQUEST), r"`motion_plan_request`.*not both"),
        (dict(scene="s-x", motion_plan_request=""), r"`motion_plan_request`: empty"),
        (dict(scene="s-x", motion_plan_request=42), r"`motion_plan_request`"),
        (dict(ok, timeout=0.0), r"`timeout`"),
        (dict(ok, timeout=math.nan), r"`timeout`"),
        (dict(ok, goal_bias=1.0), r"`goal_bias`"),
        (dict(ok, range=0.0), r"`range`"),
        (dict(ok, resolution=-1.0), r"`resolution`"),
        (dict(ok, tolerance=0.0), r"`tolerance`"),
        (dict(ok, padding=-0.01), r"`padding`"),
        (dict(ok, max_goals=0), r"`max_goals`"),
        (dict(ok, start_state_max_bounds_error=2.0), r"`start_state_max_bounds_error`"),
        (dict(ok, planning_joints="panda_joint1"), r"`planning_joints`"),
        (dict(ok, seed=-1), r"`seed`"),
        (dict(ok, smoothing_passes=1.5), r"`smoothing_passes`"),
        (dict(ok, smoothing_passes=9), r"`smoothing_passes`"),
        (dict(ok, resolution=1e300), r"`resolution`"),
        (dict(ok, max_goals=65), r"`max_goals`"),
        (dict(ok, tolerance=1e300), r"`tolerance`"),
        (dict(ok, padding=2.0), r"`padding`"),
        (dict(ok, base=[1, 0, 0]), r"`base`"),
        (dict(ok, grpc_timeout=0.0), r"`grpc_timeout`"),
        (dict(ok, start=None, goal=None, goal_joints={"panda_joint1": 0.1}), r"`joint_names`"),
    ]
    try:
        for kwargs, match in bad:
            with pytest.raises(ValueError, match=match):
                offline.plan(rid, **kwargs)
        with pytest.raises(ValueError, match=r"`robot`: required without `scene`"):
            offline.plan(None, start=start, goal=goal)
        # The same arguments, well formed, do reach for the (absent) server.
        with pytest.raises(SublevelError) as e:
            offline.plan(rid, **ok, grpc_timeout=2.0)
        assert e.value.code in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED)
    finally:
        offline.close()
