"""Robots against a real server: the MotionBenchMaker Panda (data/robots/panda) uploaded and checked
in imported MotionBenchMaker planning scenes against references computed independently of the
server — the URDF's joint limits, the mesh-exact labels of data/robots/mbm_panda/labels_obj.csv
(pinocchio + coal on the collision meshes: verdicts and minimum distances), central finite
differences of the distance, and the configuration checks along a motion."""

import csv
import json
import math
import xml.etree.ElementTree as ET
from collections import defaultdict
from functools import lru_cache
from pathlib import Path

import grpc
import numpy as np
import pytest

from sublevel_client import ConfigurationColumns, MotionColumns, Pose, RobotInfo, SublevelError

REPO = Path(__file__).resolve().parents[3]
PANDA = REPO / "data" / "robots" / "panda"
MBM = REPO / "data" / "robots" / "mbm_panda"
JOINTS = [f"panda_joint{i}" for i in range(1, 8)]

# Scenes checked against their labels (scene 1 of each scenario): the verdict and distance tests
# run on all 200 labelled configurations of each.
SCENARIOS = ["bookshelf_small", "bookshelf_tall", "bookshelf_thin", "box", "cage", "table_pick", "table_under_pick"]

DIST_TOL = 1e-5  # meters: the labels' distances are printed to 1e-6 m
TOLERANCE = 1e-3  # meters: the motions' contact tolerance (the server's default)


def urdf_limits(path):
    """{joint: (lower, upper)} of the URDF's revolute and prismatic joints, read with ElementTree."""
    out = {}
    for j in ET.parse(path).getroot().iter("joint"):
        if j.get("type") in ("revolute", "prismatic"):
            lim = j.find("limit")
            out[j.get("name")] = (float(lim.get("lower")), float(lim.get("upper")))
    return out


@lru_cache(maxsize=None)
def labels(scenario, scene):
    """The labelled configurations of one scene: q (200, 7) for panda_joint1..7 (columns q1..q7),
    and per row kind, idx, collides, collides_world, collides_self, min_world_dist_m (meters)."""
    rows = defaultdict(list)
    with open(MBM / "labels_obj.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["scenario"] == scenario and int(r["scene"]) == scene:
                for k in ("idx", "collides", "collides_world", "collides_self"):
                    rows[k].append(int(r[k]))
                rows["kind"].append(r["kind"])
                rows["dist"].append(float(r["min_world_dist_m"]))
                rows["q"].append([float(r[f"q{i}"]) for i in range(1, 8)])
    assert rows["q"], f"no labels for {scenario} scene {scene}"
    out = {k: np.array(v) for k, v in rows.items()}
    out["collides"] = out["collides"].astype(bool)
    out["collides_world"] = out["collides_world"].astype(bool)
    out["collides_self"] = out["collides_self"].astype(bool)
    return out


def scene_file(scenario, scene=1):
    return MBM / "scenes" / scenario / f"scene{scene:04d}.yaml"


@pytest.fixture(scope="module")
def panda(client):
    info = client.upload_robot(PANDA / "panda.robot.json")
    yield info
    client.delete_robot(info.robot_id)


@pytest.fixture(scope="module")
def mbm_scenes(client):
    """Scene 1 of each scenario in SCENARIOS, imported: {scenario: scene id}."""
    ids = {s: client.import_scene(scene_file(s), name=f"{s} scene0001").scene_id for s in SCENARIOS}
    yield ids
    for scene in ids.values():
        client.delete_scene(scene)


def test_the_panda_uploads_with_the_urdf_joints_and_limits(client, panda):
    assert isinstance(panda, RobotInfo)
    assert panda.joint_names == JOINTS
    assert panda.name == "panda"
    limits = urdf_limits(PANDA / "panda.urdf")
    np.testing.assert_allclose(panda.lower, [limits[j][0] for j in JOINTS], rtol=0, atol=1e-12)
    np.testing.assert_allclose(panda.upper, [limits[j][1] for j in JOINTS], rtol=0, atol=1e-12)
    # 11 collision geometries on 11 links (the fingers' finger.obj twice); the SRDF leaves 21 pairs.
    assert panda.geometries == 11
    assert len(panda.link_names) == 11 and "panda_hand" in panda.link_names
    assert panda.self_pairs == 21

    again = client.get_robot(panda.robot_id)
    assert again.joint_names == panda.joint_names and again.robot_id == panda.robot_id
    np.testing.assert_array_equal(again.lower, panda.lower)
    assert panda.robot_id in [r.robot_id for r in client.list_robots()]

    with pytest.raises(SublevelError) as e:
        client.get_robot("r-does-not-exist")
    assert e.value.code == grpc.StatusCode.NOT_FOUND


# A two-joint robot of exact spheres, answered in closed form: a carriage (a ball of radius RC) slides
# along x (joint "slide", meters) and carries an arm whose ball (radius RA) sits ARM meters out along
# the arm's x axis, swung about z (joint "swing", radians).
RC, RA, ARM = 0.1, 0.05, 0.5
SLIDER_URDF = f"""<?xml version="1.0"?>
<robot name="slider">
  <link name="base"/>
  <link name="carriage"><collision><geometry><sphere radius="{RC}"/></geometry></collision></link>
  <link name="arm"><collision><origin xyz="{ARM} 0 0"/><geometry><sphere radius="{RA}"/></geometry></collision></link>
  <joint name="slide" type="prismatic"><parent link="base"/><child link="carriage"/><axis xyz="1 0 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="swing" type="revolute"><parent link="carriage"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-3.2" upper="3.2" effort="1" velocity="1"/></joint>
</robot>
"""
# The world: a ball of radius RO at O and the floor z <= FLOOR.
RO, O, FLOOR = 0.2, np.array([2.0, 0.0, 0.0]), -0.5


def slider_file():
    identity = {"translation": [0.0, 0.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0]}
    return json.dumps({
        "format": "sublevel.robot.v1",
        "name": "slider",
        "urdf": SLIDER_URDF,
        "allowed_pairs": [],
        "geometries": [
            {"link": "carriage", "index": 0, "origin": identity, "primitive": {"primitive": "sphere", "radius": RC}},
            {"link": "arm", "index": 0, "origin": {**identity, "translation": [ARM, 0.0, 0.0]},
             "primitive": {"primitive": "sphere", "radius": RA}},
        ],
    }).encode()


def slider_closest(q, base=np.zeros(3)):
    """(distance, link, object, robot witness, object witness, d distance / d q) in closed form."""
    x, th = q
    c = base + np.array([x, 0.0, 0.0])
    a = c + ARM * np.array([math.cos(th), math.sin(th), 0.0])
    dc_dq = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]])  # columns: d/dx, d/dθ
    da_dq = np.array([[1.0, -ARM * math.sin(th)], [0.0, ARM * math.cos(th)], [0.0, 0.0]])
    out = []
    for link, p, r, dp in (("carriage", c, RC, dc_dq), ("arm", a, RA, da_dq)):
        n = (O - p) / np.linalg.norm(O - p)
        out.append((np.linalg.norm(O - p) - r - RO, link, "ball", p + r * n, O - RO * n, -n @ dp))
        down = np.array([0.0, 0.0, -1.0])
        out.append((p[2] - r - FLOOR, link, "floor", p + r * down, np.array([p[0], p[1], FLOOR]), -down @ dp))
    return min(out, key=lambda o: o[0])


@pytest.fixture(scope="module")
def slider(client):
    info = client.upload_robot(slider_file())
    scene = client.create_scene("slider world")
    ball = client.add_instance(scene, client.upload_primitive("sphere", radius=RO), Pose(t=O))
    floor = client.add_instance(scene, client.upload_primitive("halfspace", normal=(0, 0, 1), offset=FLOOR))
    yield info, scene, {ball: "ball", floor: "floor"}
    client.delete_scene(scene)
    client.delete_robot(info.robot_id)


def test_a_robot_of_spheres_answers_closed_forms(client, slider):
    info, scene, objects = slider
    assert (info.name, info.joint_names, info.link_names) == ("slider", ["slide", "swing"], ["carriage", "arm"])
    np.testing.assert_array_equal(info.lower, [-2.0, -3.2])
    np.testing.assert_array_equal(info.upper, [2.0, 3.2])
    assert info.geometries == 2

    named = client.upload_robot(slider_file().decode(), name="slider (text)")
    assert named.name == "slider (text)" and named.robot_id != info.robot_id
    client.delete_robot(named.robot_id)
    with pytest.raises(SublevelError) as e:
        client.get_robot(named.robot_id)
    assert e.value.code == grpc.StatusCode.NOT_FOUND

    rng = np.random.default_rng(7)
    q = np.column_stack([rng.uniform(-1.0, 1.2, 40), rng.uniform(-3.1, 3.1, 40)])
    for base in (np.zeros(3), np.array([0.1, -0.2, 0.3])):
        r = client.check_configurations(info.robot_id, q, scene=scene, gradient=True, base=Pose(t=base))
        assert not r.collides.any() and r.converged.all()
        for k in range(len(q)):
            d, link, obj, wr, wo, grad = slider_closest(q[k], base)
            assert abs(r.distance[k] - d) <= 1e-9
            assert (r.robot_link[k], r.robot_geometry[k], objects[r.world_object[k]]) == (link, link, obj)
            np.testing.assert_allclose(r.witnesses[k, 0], wr, atol=1e-9)
            np.testing.assert_allclose(r.witnesses[k, 1], wo, atol=1e-9)
            np.testing.assert_allclose(r.gradient[k], grad, atol=1e-9)

    hits = client.check_configurations(info.robot_id, [[1.75, math.pi], [1.3, 0.0], [0.0, 0.0]], scene=scene, distance=True)
    np.testing.assert_array_equal(hits.collides, [True, True, False])
    np.testing.assert_array_equal(hits.world, [True, True, False])
    assert hits.robot_link[:2] == ["carriage", "arm"] and [objects[o] for o in hits.world_object[:2]] == ["ball", "ball"]
    np.testing.assert_array_equal(hits.distance[:2], [0.0, 0.0])
    # Padding: a world pair closer than it collides (the carriage 0.2 m from the ball here).
    q = [1.5, math.pi]
    d0 = slider_closest(q)[0]
    assert abs(d0 - 0.2) < 1e-12
    pad = client.check_configurations(info.robot_id, q, scene=scene, padding=d0 - 1e-6, self_collision=False)
    assert not pad.collides[0]
    pad = client.check_configurations(info.robot_id, q, scene=scene, padding=d0 + 1e-6, self_collision=False)
    assert pad.collides[0] and pad.world[0] and pad.robot_link[0] == "carriage"
    # The self pair (carriage, arm), ARM - RC - RA = 0.35 m apart at every configuration: the same
    # padding rule; no scene checks it alone.
    assert info.self_pairs == 1
    gap = ARM - RC - RA
    alone = client.check_configurations(info.robot_id, [[0.0, 0.0]] * 2, padding=gap - 1e-6)
    assert not alone.collides.any()
    alone = client.check_configurations(info.robot_id, [0.0, 0.0], padding=gap + 1e-6)
    assert alone.self_collision[0] and not alone.world[0]
    assert {alone.self_link_a[0], alone.self_link_b[0]} == {"carriage", "arm"}
    assert not client.check_configurations(info.robot_id, [0.0, 0.0], padding=gap + 1e-6, self_collision=False).collides[0]


def test_an_attached_ball_moves_with_its_link(client, slider):
    info, scene, objects = slider
    # A tool ball of radius 0.03 held 0.2 m beyond the arm's ball, along the arm: at slide 0.9 and
    # swing 0 its center is at x = 1.6, 0.4 − 0.03 − RO = 0.17 m from the obstacle ball, closer
    # than the carriage to the floor (0.4) or the arm's ball to the obstacle (0.35).
    tool = {"link": "arm", "name": "tool", "kind": "sphere", "radius": 0.03, "origin": Pose(t=[ARM + 0.2, 0, 0])}
    r = client.check_configurations(info.robot_id, [0.9, 0.0], scene=scene, distance=True, attached=[tool])
    assert abs(r.distance[0] - 0.17) <= 1e-9
    assert (r.robot_link[0], r.robot_geometry[0], objects[r.world_object[0]]) == ("arm", "tool", "ball")
    np.testing.assert_allclose(r.witnesses[0, 0], [1.63, 0.0, 0.0], atol=1e-9)
    # Without it, the closed form of the bare robot.
    bare = client.check_configurations(info.robot_id, [0.9, 0.0], scene=scene, distance=True)
    assert abs(bare.distance[0] - slider_closest([0.9, 0.0])[0]) <= 1e-9
    with pytest.raises(SublevelError) as e:
        client.check_configurations(info.robot_id, [0.9, 0.0], scene=scene, attached=[{**tool, "link": "nope"}])
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and "attached[0].link" in e.value.field


CUBE_OBJ = """v -0.5 -0.5 -0.5\nv 0.5 -0.5 -0.5\nv 0.5 0.5 -0.5\nv -0.5 0.5 -0.5
v -0.5 -0.5 0.5\nv 0.5 -0.5 0.5\nv 0.5 0.5 0.5\nv -0.5 0.5 0.5
f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8
"""


def test_a_robot_fitted_on_the_server_from_its_urdf_meets_the_closed_form(client, tmp_path):
    # A cube mesh of side 0.2 (as a ROS package) on a prismatic joint along x; a wall box of half
    # side 0.1 at x = 1.1: the cube, centered at x = slide, is 1.1 − 0.1 − 0.1 − slide away.
    pkg = tmp_path / "pkgs" / "parts" / "meshes"
    pkg.mkdir(parents=True)
    (pkg / "cube.obj").write_text(CUBE_OBJ)
    urdf = tmp_path / "robot" / "cube.urdf"
    urdf.parent.mkdir()
    urdf.write_text("""<robot name="cube"><link name="base"/>
      <link name="block"><collision><geometry><mesh filename="package://parts/meshes/cube.obj" scale="0.2 0.2 0.2"/>
      </geometry></collision></link>
      <joint name="slide" type="prismatic"><parent link="base"/><child link="block"/><axis xyz="1 0 0"/>
        <limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>""")
    updates = []
    info = client.fit_robot(urdf, package_dirs=[tmp_path / "elsewhere", tmp_path / "pkgs"], tolerance=0.2,
                            max_parts=2, progress=updates.append, timeout=120)
    assert (info.name, info.joint_names, info.geometries) == ("cube", ["slide"], 1)
    assert updates and updates[-1].robot_id == info.robot_id
    scene = client.create_scene("wall")
    client.add_instance(scene, client.upload_primitive("box", size=(0.2, 0.2, 0.2)), Pose(t=[1.1, 0, 0]))
    slides = np.array([[-0.5], [0.0], [0.5], [0.95]])
    r = client.check_configurations(info.robot_id, slides, scene=scene, distance=True)
    np.testing.assert_allclose(r.distance[:3], 0.9 - slides[:3, 0], atol=1e-9)
    np.testing.assert_array_equal(r.collides, [False, False, False, True])
    client.delete_scene(scene)
    client.delete_robot(info.robot_id)
    with pytest.raises(FileNotFoundError):
        client.fit_robot(urdf, package_dirs=[tmp_path / "elsewhere"])


def test_link_padding_inflates_one_link(client, slider):
    info, scene, objects = slider
    # At slide 1.5, swing π the carriage is 0.2 m from the ball (the arm farther): its padding
    # decides, the arm's does not; a motion stops where the padded carriage reaches the ball.
    q = [1.5, math.pi]
    d0 = slider_closest(q)[0]
    for pad, collides in ((d0 - 1e-6, False), (d0 + 1e-6, True)):
        r = client.check_configurations(info.robot_id, q, scene=scene, self_collision=False,
                                        link_padding={"carriage": pad})
        assert bool(r.collides[0]) == collides
    r = client.check_configurations(info.robot_id, q, scene=scene, self_collision=False, distance=True,
                                    link_padding={"arm": d0 + 1e-6})
    assert not r.collides[0] and abs(r.distance[0] - d0) <= 1e-9
    # Sliding the carriage (swing π, arm behind) towards the ball from 0: with 0.1 m of padding the
    # contact is where the carriage is 0.1 m away, slide = 2 − RO − RC − 0.1 = 1.6.
    m = client.check_motions(info.robot_id, [0.0, math.pi], [2.0, math.pi], scene=scene, tolerance=1e-6,
                             link_padding={"carriage": 0.1})
    assert not m.valid[0] and abs(m.contact_t[0] * 2.0 - 1.6) <= 1e-5
    with pytest.raises(SublevelError) as e:
        client.check_configurations(info.robot_id, q, scene=scene, link_padding={"nope": 0.1})
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and "link_padding[nope]" in e.value.field


def test_motions_of_the_sphere_robot_stop_at_the_closed_form_contact(client, slider):
    info, scene, objects = slider
    tol = 1e-3

    def contact_interval(distance_at, t_hi):
        """The parameters in [0, t_hi] where the distance first falls to tol, and to 0 (bisection)."""
        out = []
        for level in (tol, 0.0):
            lo, hi = 0.0, t_hi
            for _ in range(100):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if distance_at(mid) > level else (lo, mid)
            out.append(lo)
        return out

    q0 = np.array([[0.0, math.pi], [0.0, 0.0], [1.3, math.pi], [-1.0, 1.0]])
    q1 = np.array([[1.9, math.pi], [1.9, 0.0], [1.3, 0.0], [0.5, 2.0]])
    m = client.check_motions(info.robot_id, q0, q1, scene=scene, tolerance=tol)
    np.testing.assert_array_equal(m.valid, [False, False, False, True])
    assert m.decided.all()
    assert m.robot_link[:3] == ["carriage", "arm", "arm"] and [objects[o] for o in m.other[:3]] == ["ball"] * 3
    for k in range(3):
        lo, hi = contact_interval(lambda t: slider_closest(q0[k] + t * (q1[k] - q0[k]))[0], 1.0)
        assert lo - 1e-9 <= m.contact_t[k] <= hi + 1e-9, (k, lo, m.contact_t[k], hi)
        np.testing.assert_allclose(m.contact_configuration[k], q0[k] + m.contact_t[k] * (q1[k] - q0[k]), atol=1e-12)
    # The carriage meets the ball when 2 - x = RC + RO: at x = 1.7 of 1.9.
    assert abs(m.contact_t[0] - 1.7 / 1.9) <= tol / 1.9 + 1e-9
    assert math.isnan(m.contact_t[3]) and not m.self_contact.any()


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_verdicts_and_distances_equal_the_mesh_labels(client, panda, mbm_scenes, scenario):
    lab = labels(scenario, 1)
    scene = mbm_scenes[scenario]
    verdict = client.check_configurations(panda.robot_id, lab["q"], scene=scene, joint_names=JOINTS)
    assert isinstance(verdict, ConfigurationColumns) and len(verdict) == len(lab["q"])
    assert verdict.gradient is None
    assert np.all(np.isnan(verdict.distance))
    misses = np.flatnonzero(lab["collides"] & ~verdict.collides)
    false = np.flatnonzero(~lab["collides"] & verdict.collides)
    assert len(misses) == 0, f"{scenario}: labelled colliding, answered free: idx {lab['idx'][misses].tolist()}"
    assert len(false) == 0, f"{scenario}: labelled free, answered colliding: idx {lab['idx'][false].tolist()}"
    np.testing.assert_array_equal(verdict.world, lab["collides_world"])
    np.testing.assert_array_equal(verdict.self_collision, lab["collides_self"])
    for c in np.flatnonzero(verdict.self_collision):
        assert verdict.self_link_a[c] and verdict.self_link_b[c]
    assert lab["collides"].any() and (~lab["collides"]).any()  # both kinds are exercised

    full = client.check_configurations(panda.robot_id, lab["q"], scene=scene, distance=True)
    np.testing.assert_array_equal(full.collides, lab["collides"])
    np.testing.assert_array_equal(full.world, lab["collides_world"])
    free = ~lab["collides_world"]
    err = full.distance[free] - lab["dist"][free]
    worst = int(np.argmax(np.abs(err)))
    assert np.all(np.abs(err) <= DIST_TOL), (
        f"{scenario}: distance off by {err[worst]:.3g} m at idx {lab['idx'][free][worst]}"
    )
    assert np.all(err <= DIST_TOL)  # never above the meshes' distance
    assert np.all(full.distance[~free] == 0.0)
    # The witnesses: the robot's and the object's closest points, as far apart as the distance.
    w = full.witnesses[free]
    assert w.shape == (free.sum(), 2, 3) and np.all(np.isfinite(w))
    np.testing.assert_allclose(np.linalg.norm(w[:, 0] - w[:, 1], axis=1), full.distance[free], atol=1e-6)
    assert all(full.robot_link[c] in panda.link_names and full.world_object[c] for c in np.flatnonzero(free))
    assert np.all(np.isnan(full.witnesses[~free]))
    assert full.converged.all()
    assert full.pairs_pruned + full.pairs_model + full.pairs_exact > 0


def test_gradient_matches_central_differences(client, panda, mbm_scenes):
    scenario = "bookshelf_small"
    lab = labels(scenario, 1)
    scene = mbm_scenes[scenario]
    candidates = np.flatnonzero(~lab["collides"] & (lab["dist"] > 0.01))[::9][:6]
    assert len(candidates) >= 4
    q = lab["q"][candidates]
    at = client.check_configurations(panda.robot_id, q, scene=scene, gradient=True)
    assert at.gradient.shape == (len(q), 7) and at.joint_names == JOINTS
    assert np.all(np.isfinite(at.gradient))
    h = 1e-6
    compared = 0
    for c in range(len(q)):
        steps = np.concatenate([q[c] + h * np.eye(7), q[c] - h * np.eye(7)])
        d = client.check_configurations(panda.robot_id, steps, scene=scene, distance=True)
        pairs = {(d.robot_geometry[k], d.world_object[k]) for k in range(14)}
        if pairs != {(at.robot_geometry[c], at.world_object[c])}:
            continue  # the closest pair changes within the step: the distance has a kink here
        fd = (d.distance[:7] - d.distance[7:]) / (2 * h)
        tol = np.maximum(1e-4, 1e-3 * np.abs(fd))
        assert np.all(np.abs(at.gradient[c] - fd) <= tol), (
            f"idx {lab['idx'][candidates[c]]}: gradient {at.gradient[c]} vs differences {fd}"
        )
        compared += 1
    assert compared >= 3


def _segment(q0, q1, ts):
    return q0[None, :] + np.asarray(ts)[:, None] * (q1 - q0)[None, :]


def test_motions_are_free_or_stop_at_their_first_contact(client, panda, mbm_scenes):
    scenario = "bookshelf_small"
    lab = labels(scenario, 1)
    scene = mbm_scenes[scenario]
    line = np.flatnonzero(lab["kind"] == "line")  # 100 samples of the start–goal segment, in order
    free = ~lab["collides"]
    clear = free & (lab["dist"] > 0.01)
    # Two neighbouring clear samples (a short free motion), and the last clear sample before the
    # first colliding one on the segment to that one.
    near = next(k for k in range(len(line) - 1) if clear[line[k]] and clear[line[k + 1]])
    hit = next(j for j in range(len(line)) if lab["collides"][line[j]])
    into = (max(k for k in range(hit) if clear[line[k]]), hit)
    q0 = lab["q"][[line[near], line[into[0]]]]
    q1 = lab["q"][[line[near + 1], line[into[1]]]]
    m = client.check_motions(panda.robot_id, q0, q1, scene=scene, tolerance=TOLERANCE)
    assert isinstance(m, MotionColumns) and len(m) == 2 and m.joint_names == JOINTS
    assert m.decided.all() and (m.steps > 0).all()

    # The free motion: proven free, and every one of 64 states along it is free.
    assert m.valid[0] and math.isnan(m.contact_t[0]) and np.all(np.isnan(m.contact_configuration[0]))
    assert m.robot_link[0] == "" and m.other[0] == ""
    states = client.check_configurations(panda.robot_id, _segment(q0[0], q1[0], np.linspace(0, 1, 64)), scene=scene)
    assert not states.collides.any()

    # Into a collision: invalid, the first contact inside (0, 1], a configuration there within
    # the tolerance of an obstacle, and the motion free before it.
    assert not m.valid[1]
    t = m.contact_t[1]
    assert 0.0 < t <= 1.0
    np.testing.assert_allclose(m.contact_configuration[1], q0[1] + t * (q1[1] - q0[1]), atol=1e-9)
    assert m.robot_link[1] in panda.link_names and m.other[1]
    at = client.check_configurations(
        panda.robot_id, m.contact_configuration[1], scene=scene, padding=TOLERANCE, distance=True
    )
    plain = client.check_configurations(panda.robot_id, m.contact_configuration[1], scene=scene, distance=True)
    assert at.collides[0] or plain.distance[0] <= TOLERANCE
    before = client.check_configurations(panda.robot_id, _segment(q0[1], q1[1], np.linspace(0, t, 64)[:-1]), scene=scene)
    assert not before.collides.any()

    # One motion given as plain (7,) vectors.
    one = client.check_motions(panda.robot_id, q0[0], q1[0], scene=scene)
    assert len(one) == 1 and one.valid[0]


def test_sampled_motions_answer_as_configuration_checks_of_their_samples(client, panda, mbm_scenes):
    """``resolution`` > 0: motion k's samples t = i / n, n = max(1, ceil(|q1 - q0| * resolution)),
    i = 1 .. n, recomputed here and checked by CheckConfigurations: the motion is valid exactly
    when none collides; otherwise its contact_t is one of its colliding samples, and its contact
    configuration that sample."""
    scene = mbm_scenes["bookshelf_small"]
    q = labels("bookshelf_small", 1)["q"]
    q0, q1 = q[:24], q[1:25]
    resolution = 6.0
    m = client.check_motions(panda.robot_id, q0, q1, scene=scene, resolution=resolution)
    assert len(m) == len(q0) and m.decided.all() and (m.steps == 0).all()
    valid = invalid = 0
    for k in range(len(q0)):
        # The length as the server sums it: in joint order.
        length = math.sqrt(sum(float(d) * float(d) for d in q1[k] - q0[k]))
        n = max(1, math.ceil(length * resolution))
        ts = np.arange(1, n + 1) / n
        samples = q0[k][None, :] + ts[:, None] * (q1[k] - q0[k])[None, :]
        states = client.check_configurations(panda.robot_id, samples, scene=scene)
        assert m.valid[k] == (not states.collides.any()), k
        if m.valid[k]:
            valid += 1
            assert m.samples[k] == n and math.isnan(m.contact_t[k]) and m.robot_link[k] == ""
            continue
        invalid += 1
        i = int(round(m.contact_t[k] * n))
        assert m.contact_t[k] == i / n, k
        assert states.collides[i - 1], k
        np.testing.assert_array_equal(m.contact_configuration[k], samples[i - 1])
        assert 0 < m.samples[k] <= n
        assert m.robot_link[k] in panda.link_names and m.other[k]
    assert valid >= 3 and invalid >= 3, (valid, invalid)

    # The certified check of the same motions: one proven free has no colliding sample.
    certified = client.check_motions(panda.robot_id, q0, q1, scene=scene)
    assert (certified.samples == 0).all()
    assert m.valid[certified.valid].all()
    with pytest.raises(ValueError, match="resolution"):
        client.check_motions(panda.robot_id, q0, q1, scene=scene, resolution=-1.0)


def test_self_collision_and_base_pose(client, panda):
    scenario = "bookshelf_small"
    lab = labels(scenario, 1)
    only_self = np.flatnonzero(lab["collides_self"] & ~lab["collides_world"])
    only_world = np.flatnonzero(lab["collides_world"] & ~lab["collides_self"])
    free = np.flatnonzero(~lab["collides"] & (lab["dist"] > 0.01))
    assert len(only_self) and len(only_world) and len(free)
    pick = np.concatenate([only_self[:3], only_world[:3], free[:3]])
    q = lab["q"][pick]

    imported = client.import_scene(scene_file(scenario))
    try:
        a = client.check_configurations(panda.robot_id, q, scene=imported.scene_id, distance=True)
        np.testing.assert_array_equal(a.collides, lab["collides"][pick])
        no_self = client.check_configurations(panda.robot_id, q, scene=imported.scene_id, self_collision=False)
        assert not no_self.self_collision.any()
        np.testing.assert_array_equal(no_self.collides, lab["collides_world"][pick])

        # The robot and the whole scene moved by the same rigid motion: the same answers, the
        # witnesses moved with them.
        shift = Pose(quat=(math.cos(0.35), 0.0, 0.0, math.sin(0.35)), t=(2.0, -1.0, 0.5))
        scene = client.get_scene(imported.scene_id)
        client.set_poses(imported.scene_id, {i.instance_id: shift @ i.pose for i in scene.instances})
        b = client.check_configurations(panda.robot_id, q, scene=imported.scene_id, distance=True, base=shift)
        np.testing.assert_array_equal(b.collides, a.collides)
        np.testing.assert_array_equal(b.world, a.world)
        np.testing.assert_array_equal(b.self_collision, a.self_collision)
        ok = ~a.world
        np.testing.assert_allclose(b.distance[ok], a.distance[ok], atol=1e-6)
        for side in (0, 1):
            np.testing.assert_allclose(b.witnesses[ok, side], shift.apply(a.witnesses[ok, side]), atol=1e-6)
        assert b.world_object == a.world_object
        # The base as a 4x4 matrix answers the same.
        c = client.check_configurations(panda.robot_id, q, scene=imported.scene_id, distance=True, base=shift.matrix())
        np.testing.assert_allclose(c.distance[ok], b.distance[ok], atol=1e-9)

        # No scene: self-collision only.
        alone = client.check_configurations(panda.robot_id, q, distance=True)
        np.testing.assert_array_equal(alone.collides, lab["collides_self"][pick])
        assert not alone.world.any()
    finally:
        client.delete_scene(imported.scene_id)


def test_errors_name_what_is_wrong(client, panda, mbm_scenes):
    q = labels("table_pick", 1)["q"][:2]
    with pytest.raises(ValueError, match=r"`q`.*\(configurations, 7\)"):
        client.check_configurations(panda.robot_id, q[:, :6])
    with pytest.raises(ValueError, match=r"`q`.*\(configurations, 6\)"):
        client.check_configurations(panda.robot_id, q, joint_names=JOINTS[:6])
    with pytest.raises(ValueError, match=r"`q1`"):
        client.check_motions(panda.robot_id, q, q[:1])
    with pytest.raises(ValueError, match=r"`q0`"):
        client.check_motions(panda.robot_id, q[:, :5], q)
    with pytest.raises(ValueError, match=r"`q`.*not finite"):
        client.check_configurations(panda.robot_id, np.where(np.eye(2, 7) > 0, np.nan, q))
    with pytest.raises(ValueError, match=r"`joint_names`"):
        client.check_configurations(panda.robot_id, q[:, :2], joint_names=["panda_joint1", "panda_joint1"])
    with pytest.raises(ValueError, match=r"`base`"):
        client.check_configurations(panda.robot_id, q, base=[1, 0, 0])

    for call in (
        lambda: client.get_robot("r-does-not-exist"),
        lambda: client.check_configurations("r-does-not-exist", q),
        lambda: client.check_configurations("r-does-not-exist", q, joint_names=JOINTS),
        lambda: client.check_motions("r-does-not-exist", q, q, joint_names=JOINTS),
        lambda: client.delete_robot("r-does-not-exist"),
    ):
        with pytest.raises(SublevelError) as e:
            call()
        assert e.value.code == grpc.StatusCode.NOT_FOUND, e.value

    names = JOINTS[:6] + ["panda_joint_nope"]
    with pytest.raises(SublevelError) as e:
        client.check_configurations(panda.robot_id, q, joint_names=names, scene=mbm_scenes["bookshelf_small"])
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert e.value.field and "joint_names" in e.value.field, e.value
    assert "panda_joint_nope" in e.value.message

    with pytest.raises(SublevelError) as e:
        client.upload_robot(b'{"format": "sublevel.robot.v1"}')
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
