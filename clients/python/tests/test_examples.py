"""The examples the READMEs name, run as a user runs them: each as its own process against the
session's `serve --demo` server (conftest.py), with small arguments so that each takes seconds,
its output checked against independent references (the mesh labels of
data/robots/mbm_panda/labels_obj.csv, a path found). An example whose packages the test
environment lacks (requirements-test.txt) is skipped, naming the missing module.

`test_every_example_the_readmes_name_is_run_here` keeps this list complete: an example named in
README.md or clients/python/README.md without a test here fails it. README.md's Python lines run as
written too."""

import csv
import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[3]
EXAMPLES = REPO / "clients" / "python" / "examples"
READMES = [REPO / "README.md", REPO / "clients" / "python" / "README.md"]

# Every example the READMEs name, and the test below that runs it. `mbm_coal.py` is the
# pinocchio + coal checker of `plan_mbm.py --checker coal` (a module, not a program of its own).
TESTED = {
    "clients/python/examples/check_panda.py": "test_check_panda_prints_the_mesh_labels_verdicts",
    "clients/python/examples/round_trips.py": "test_round_trips_times_every_call",
    "clients/python/examples/plan_ompl.py": "test_plan_ompl_finds_a_path_through_the_walls",
    "clients/python/examples/plan_mbm.py": "test_plan_mbm_plans_a_bookshelf_problem_with_certified_edges",
    "clients/python/examples/trajectory_mbm.py": "test_trajectory_mbm_times_and_checks_each_plan",
    "clients/python/examples/mbm_coal.py": "test_plan_mbm_with_the_coal_checker",
    "clients/python/examples/depth_stream.py": "test_depth_stream_keeps_one_point_per_voxel",
    "examples/client.rs": "test_the_rust_example_client_slides_the_chair_through_the_human",
}


def need(module):
    """Skips the test when ``module`` does not import in this environment."""
    if importlib.util.find_spec(module) is None:
        pytest.skip(f"module `{module}` is not installed (not in requirements-test.txt)")


def run(args, timeout):
    """Runs ``args`` from the repository root (as the READMEs do); returns its stdout after
    checking that it exited 0."""
    proc = subprocess.run(
        [str(a) for a in args], cwd=REPO, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL
    )
    assert proc.returncode == 0, (
        f"{' '.join(map(str, args))} exited {proc.returncode}\n"
        f"stdout:\n{proc.stdout[-4000:]}\nstderr:\n{proc.stderr[-4000:]}"
    )
    return proc.stdout


def example(name, server, *args, timeout=300):
    return run([sys.executable, EXAMPLES / name, "--addr", server.addr, *args], timeout)


def test_every_example_the_readmes_name_is_run_here():
    named = set()
    for readme in READMES:
        text = readme.read_text()
        for m in re.finditer(r"(?<![\w/.])((?:clients/python/)?examples/[\w./-]+\.(?:py|rs))", text):
            path = m.group(1)
            # The Python README names its examples from its own folder, the Rust ones from the root.
            if readme.parent.name == "python" and path.endswith(".py") and not path.startswith("clients/"):
                path = "clients/python/" + path
            named.add(path)
    assert "clients/python/examples/check_panda.py" in named
    for path in named:
        assert (REPO / path).is_file(), f"{path}, named by a README, does not exist"
    assert named <= set(TESTED), f"examples the READMEs name without a test here: {sorted(named - set(TESTED))}"
    module = sys.modules[__name__]
    for path, test in TESTED.items():
        assert (REPO / path).is_file(), path
        assert callable(getattr(module, test, None)), test


def bookshelf_labels():
    """{(q1..q7 as written): collides} of bookshelf_small scene 1, the demo's `mbm_bookshelf`."""
    out = {}
    with open(REPO / "data" / "robots" / "mbm_panda" / "labels_obj.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["scenario"] == "bookshelf_small" and r["scene"] == "1":
                out[tuple(float(r[f"q{i}"]) for i in range(1, 8))] = r["collides"] == "1"
    return out


def test_check_panda_prints_the_mesh_labels_verdicts(server):
    spec = importlib.util.spec_from_file_location("check_panda", EXAMPLES / "check_panda.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    labels = bookshelf_labels()
    # The example's configurations and labels are rows of the labels file, one free, one colliding.
    want = []
    for q, label in module.CONFIGURATIONS:
        assert labels[tuple(q)] == label
        want.append("collides" if label else "free")
    assert sorted(want) == ["collides", "free"]

    out = example("check_panda.py", server, timeout=120)
    assert re.search(r"^robot panda r-\w+ \(7 joints\), scene mbm_bookshelf s-\w+$", out, re.M), out
    verdicts = re.findall(r"^q(\d): (free|collides) +distance (\S+) m, (\S*) - (\S*) +\(mesh label: (\w+)\)$", out, re.M)
    assert [v[1] for v in verdicts] == want, out
    assert [v[5] for v in verdicts] == want, out
    for k, verdict, dist, link, obj, _ in verdicts:
        assert link.startswith("panda_") and obj, out  # the closest (or colliding) pair is named
        assert (float(dist) == 0.0) == (verdict == "collides"), out
    assert "verdicts equal the mesh labels" in out


def test_the_readme_python_lines_run_as_written(server):
    # README.md's Python lines in order (the quick start, then the demo's Panda), as a user pastes
    # them into one session, the address replaced by the test server's.
    blocks = re.findall(r"```python\n(.*?)```", (REPO / "README.md").read_text(), re.S)
    assert len(blocks) == 2 and "mbm_bookshelf" in blocks[1], blocks
    code = "\n".join(blocks).replace('"127.0.0.1:50051"', repr(server.addr))
    assert server.addr in code
    code += "\nprint(list(map(bool, r.collides)), d.converged)\nc.delete_scene(scene)\nc.delete_body(chair)\n"
    out = run([sys.executable, "-c", code], timeout=120)
    assert out.splitlines()[-1] == "[False, True] True", out


def test_round_trips_times_every_call(server, restore_demo):
    out = example("round_trips.py", server, "--repeats", "3", timeout=300)
    # One row per call: its name, p50 and p99 in ms, calls and pairs per second.
    rows = {
        m.group(1): (float(m.group(2)), float(m.group(3)), int(m.group(4)), int(m.group(5)))
        for m in re.finditer(r"^(\S.*?) +(\d+\.\d{3}) +(\d+\.\d{3}) +(\d+) +(\d+)$", out, re.M)
    }
    for call in ("Distance, unary", "QueryStream step: 1 pose + 19 queries", "Query, 256 states as one array, cold"):
        assert call in rows, out
    assert len(rows) >= 15, out
    for p50, p99, calls, pairs in rows.values():
        assert 0.0 < p50 <= p99 and calls > 0 and pairs >= calls, out


def test_plan_ompl_finds_a_path_through_the_walls(server):
    need("ompl")
    # Degree-2 obstacles (each shape's ellipsoid fit in place of its higher-degree fits): the
    # uploads certify in milliseconds; the walls and the slalom are the same.
    out = example(
        "plan_ompl.py", server, "--max-degree", "2", "--png", "", "--time", "120", "--delete-bodies", timeout=600
    )
    assert re.search(r"^RRTConnect in SE\(3\), margin 0.02 m: exact solution in", out, re.M), out
    m = re.search(r"^path: (\d+) waypoints", out, re.M)
    assert m and int(m.group(1)) >= 2, out
    m = re.search(r"^clearance along the path \(\d+ states\): min (\S+) m", out, re.M)
    # Every state of the path keeps the 2 cm margin, up to the interpolation between checked states.
    assert m and float(m.group(1)) > 0.0, out
    assert "obstacle tests/data/chair_101.deg2" in out and ".deg8" not in out


def plan_mbm(server, *extra, scenarios=("bookshelf_small",)):
    """Runs plan_mbm.py on the first problem of each of ``scenarios`` with ``extra`` arguments."""
    if "service" not in extra:  # --mode service plans on the server: no OMPL
        need("ompl")
    need("yaml")
    panda = REPO / "data" / "robots" / "panda"
    return example(
        "plan_mbm.py",
        server,
        "--urdf", panda / "panda.urdf",
        "--srdf", panda / "panda.srdf",
        "--problems", REPO / "data" / "robots" / "mbm_panda" / "problems.tar.bz2",
        "--scenarios", *scenarios,
        "--limit", "1",
        *extra,
        timeout=600,
    )  # fmt: skip


def test_plan_mbm_plans_a_bookshelf_problem_with_certified_edges(server):
    out = plan_mbm(server, "--timeout", "20")
    assert re.search(r"^robot panda \(r-\w+\) from \S*panda.robot.json: 7 joints", out, re.M), out
    row = re.search(r"^bookshelf_small +(\S+) +(True|False) ", out, re.M)
    assert row, out
    # The problem is a valid one (start and goal free), solved, and its path certified.
    assert row.group(2) == "True", out
    assert re.search(r"^\| bookshelf_small \| 1 \| 1 \| 1 \| 100 \|", out, re.M), out


def test_trajectory_mbm_times_and_checks_each_plan(server, tmp_path):
    need("yaml")
    out = example(
        "trajectory_mbm.py",
        server,
        "--problems", REPO / "data" / "robots" / "mbm_panda" / "problems.tar.bz2",
        "--scenarios", "bookshelf_small", "box",
        "--limit", "1",
        "--timeout", "20",
        "--joint-limits", REPO / "data" / "robots" / "panda" / "joint_limits.yaml",
        "--json", tmp_path / "t.json",
        timeout=600,
    )  # fmt: skip
    for s in ("bookshelf_small", "box"):
        # solved 1/1, certified 1, no error, no limit violation, no colliding 1 ms sample.
        assert re.search(rf"^{s} \| 1/1 \| 1 \| 0 \| 0 \| 0 \| ", out, re.M), out
    rows = json.loads((tmp_path / "t.json").read_text())["problems"]
    assert all(r["same_duration"] and r["at_rest"] and r["on_ends"] for r in rows), rows
    assert all(r["duration"] <= r["stop_duration"] for r in rows), rows


def test_plan_mbm_service_mode_plans_each_problem_in_one_call(server, tmp_path):
    scenarios = ("bookshelf_small", "box")
    out = plan_mbm(server, "--mode", "service", "--timeout", "20", "--json", tmp_path / "text.json", scenarios=scenarios)
    assert re.search(r"^\d+ problems, mode service \(one Plan call per problem, the request sent text\)", out, re.M), out
    assert re.search(r"^robot panda \(r-\w+\) from \S*panda.robot.json: 7 joints", out, re.M), out
    for s in scenarios:
        assert re.search(rf"^{s} +scene0001.yaml +True +\d+\.\d +\d+\.\d +\d+ +\d+$", out, re.M), out
        assert re.search(rf"^\| {s} \| 1 \| 1 \| 1 \| 100 \|", out, re.M), out
    import yaml  # after plan_mbm's need("yaml")

    report = json.loads((tmp_path / "text.json").read_text())
    assert report["mode"] == "service" and report["joint_names"] == [f"panda_joint{i}" for i in range(1, 8)]
    rows = {r["scenario"]: r for r in report["problems"]}
    assert sorted(rows) == sorted(scenarios)
    for s, r in rows.items():
        # The path runs from the request's start to its goal (the request file read here), every
        # edge certified, its figures the call's.
        req = yaml.safe_load((REPO / "data" / "robots" / "mbm_panda" / "requests" / s / "request0001.yaml").read_text())
        js = dict(zip(req["start_state"]["joint_state"]["name"], req["start_state"]["joint_state"]["position"]))
        goal = {c["joint_name"]: c["position"] for c in req["goal_constraints"][0]["joint_constraints"]}
        assert r["status"] == "solved" and r["solved"] and r["certified"] and r["valid_problem"], r
        assert r["path"][0] == [js[j] for j in report["joint_names"]]
        assert r["path"][-1] == [goal[j] for j in report["joint_names"]]
        assert r["planning_time_s"] >= r["server_time_s"] > 0.0
        stages = r["goals_time_s"] + r["search_time_s"] + r["simplify_time_s"] + r["certify_time_s"]
        assert 0.0 < stages <= r["server_time_s"]
        assert r["edges_certified"] >= len(r["path"]) - 1 and r["states_checked"] > 0
        assert r["motions_checked"] >= r["edges_certified"]
    # The start and goal sent typed: the same path as the request's text.
    plan_mbm(server, "--mode", "service", "--request-as", "typed", "--timeout", "20", "--json", tmp_path / "typed.json",
             scenarios=("box",))
    typed = json.loads((tmp_path / "typed.json").read_text())["problems"]
    assert len(typed) == 1 and typed[0]["path"] == rows["box"]["path"]


def test_plan_mbm_with_the_coal_checker(server):
    need("pinocchio")  # pin==4.1.0 (pinocchio with coal): large wheels, not in requirements-test.txt
    out = plan_mbm(server, "--timeout", "5", "--checker", "coal")
    assert re.search(r"^bookshelf_small +\S+ +(True|False) ", out, re.M), out


def test_the_rust_example_client_slides_the_chair_through_the_human(server, restore_demo):
    # Built beside the server binary by `cargo test` (scripts/test) or `cargo build --example client`.
    client = server.binary.parent / "examples" / "client"
    if not client.is_file():
        pytest.skip(f"{client} is not built (cargo build --example client)")
    proc = subprocess.run(
        [str(client)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "SUBLEVEL_ADDR": server.addr},
        stdin=subprocess.DEVNULL,
    )
    assert proc.returncode == 0, f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    out = proc.stdout
    names = re.findall(r"^body (\S+) +b-\w+ degree 4 volume", out, re.M)
    assert sorted(names) == ["chair_101", "human_10"], out
    steps = re.findall(r"^ +(-?\d+\.\d\d) +(\d+\.\d{4}) +(\S+) +(true|false) ", out, re.M)
    assert len(steps) == 13, out
    assert all(conv == "true" for *_, conv in steps), out
    # Apart at the first step, overlapping (distance 0) when the chair passes through the human.
    assert float(steps[0][1]) > 0.0 and any(float(d) == 0.0 for _, d, *_ in steps), out
    # The plan: solved, every edge certified, and the round trip no shorter than the server's time.
    plan = re.search(r"^  PLAN_STATUS_SOLVED: (\d+) waypoints, length (\S+), certified true", out, re.M)
    assert plan and int(plan.group(1)) >= 2 and float(plan.group(2)) > 0.0, out
    trip = re.search(r"round trip (\S+) ms median of 21 \(the server's own time (\S+) ms", out)
    assert trip and float(trip.group(1)) >= float(trip.group(2)) > 0.0, out


def test_depth_stream_keeps_one_point_per_voxel(server):
    # The server's filter against numpy: the example's frames deprojected here and grouped by
    # their 2 cm world voxel. The timed frame is the 11th sent, frames[10 % 4].
    spec = importlib.util.spec_from_file_location("depth_stream", EXAMPLES / "depth_stream.py")
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    rng = np.random.default_rng(1)
    depth = [m.depth_frame(rng, 0.002) for _ in range(4)][2] * 1e-3
    u, v = np.meshgrid(np.arange(m.WIDTH), np.arange(m.HEIGHT))
    optical = np.stack([(u - m.CX) / m.FX * depth, (v - m.CY) / m.FY * depth, depth], axis=-1).reshape(-1, 3)
    w, x, y, z, *t = m.SENSOR
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    world = optical @ rotation.T + np.array(t)
    voxels = len(np.unique(np.floor(world / 0.02).astype(np.int64), axis=0))
    out = example("depth_stream.py", server, "--frames", "1", "--rate", "0", timeout=120)
    kept = re.search(r"points kept +median (\d+) of 307200", out)
    assert kept, out
    # float32 on the server against float64 here: points on a voxel face may fall either side.
    assert abs(int(kept.group(1)) - voxels) <= 0.01 * voxels, (kept.group(1), voxels, out)
    trip = re.search(r"round trip +median +(\S+) ms", out)
    own = re.search(r"server seconds median +(\S+) ms", out)
    assert trip and own and float(trip.group(1)) >= float(own.group(1)) > 0.0, out
