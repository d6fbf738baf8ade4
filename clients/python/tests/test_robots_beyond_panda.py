"""Robots beyond the Panda (docs/robots.md, "Robots beyond the Panda, against pinocchio + coal"): a
7-joint arm (xArm 7), a mobile manipulator with a torso (PR2) and a robot with two arms and legs
(Talos), from the PyPI package example-robot-data, fitted by `sublevel robot fit` from their files as
they are (Talos's 13 mirrored meshes and the 7-value `root_joint` of its SRDF included). The
self-collision verdicts of `sublevel robot check` on 2 000 configurations drawn in the joint limits
are compared with pinocchio + coal on the same meshes by examples/robot_agreement.py: no miss, no
false collision, the same link pairs checked."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]
TOOL = REPO / "clients" / "python" / "examples" / "robot_agreement.py"


def robots_dir() -> Path:
    """example-robot-data's robots folder (its loaders find it)."""
    for module in ("pinocchio", "example_robot_data"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"module `{module}` is not installed (requirements-test.txt installs it)")
    import example_robot_data

    return Path(example_robot_data.getModelPath("ur_description/urdf/ur5_robot.urdf")).resolve()


def test_three_robots_agree_with_pinocchio_and_coal_on_their_meshes(server, tmp_path):
    out = tmp_path / "agreement.json"
    proc = subprocess.run(
        [sys.executable, TOOL, "--sublevel", server.binary, "--robots-dir", robots_dir(), "--robot", "xarm7",
         "--robot", "pr2", "--robot", "talos", "--configs", "2000", "--seed", "1", "--out", tmp_path,
         "--json", out, "--fit-timeout", "900"],
        capture_output=True, text=True, timeout=3000, stdin=subprocess.DEVNULL,
    )
    assert proc.returncode == 0, f"stdout:\n{proc.stdout[-4000:]}\nstderr:\n{proc.stderr[-4000:]}"
    results = {r["robot"]: r for r in json.loads(out.read_text())}
    # Link pairs checked: the SRDF's disabled pairs and the pairs of one rigid body left out, as
    # pinocchio leaves them (it never pairs geometries of one joint).
    expected_pairs = {"xarm7": 11, "pr2": 239, "talos": 887}
    for name, pairs in expected_pairs.items():
        r = results[name]
        assert r["fit"]["ok"], r["fit"]
        assert r["counts"]["misses"] == 0 and r["counts"]["false_collisions"] == 0, (name, r["disagreements"])
        assert r["counts"]["both_collide"] + r["counts"]["both_free"] == 2000, r["counts"]
        assert r["counts"]["both_collide"] > 0 and r["counts"]["both_free"] > 0, r["counts"]
        assert r["pairs"]["only_sublevel"] == [] and r["pairs"]["only_pinocchio"] == [], r["pairs"]
        assert r["pairs"]["sublevel_reported"] == r["pairs"]["pinocchio_link_pairs"] == pairs, r["pairs"]
    # What was skipped and left out is said: Talos's multi-DOF group state, its gripper links on one
    # rigid body.
    talos = results["talos"]["fit"]
    assert any("srdf.group_state[0]: skipped joint `root_joint` of 7 values" in w for w in talos["warnings"]), talos
    assert len(talos["not_checked"]) == 6, talos["not_checked"]
