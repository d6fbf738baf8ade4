#!/usr/bin/env python3
"""Plan the MotionBenchMaker problems with OMPL, checked by the Sublevel service or by pinocchio + coal,
or with the service's own planner (one ``Plan`` RPC per problem).

    python clients/python/examples/plan_mbm.py --urdf data/robots/panda/panda.urdf \\
        --srdf data/robots/panda/panda.srdf --problems data/robots/mbm_panda/problems.tar.bz2 \\
        --limit 10 --timeout 1 [--mode ompl|service] [--checker sublevel|coal] [--verify] [--json out/plan_mbm.json]

Needs ``pip install ./clients/python pyyaml``, and ``ompl==2.0.1`` for ``--mode ompl``; ``--checker coal``
and ``--verify`` also ``pin==4.1.0`` (pinocchio with coal). ``--checker sublevel`` and ``--mode service``
need a running server (``sublevel serve``; ``--serve`` starts one from the binary for the run, its store
in a temporary folder).

Problems: MotionBenchMaker's layout, a tar (read in place) or a folder holding
``<scenario>_<robot>/sceneNNNN.yaml`` with ``requestNNNN.yaml`` beside it, or ``scenes/<scenario>/`` with
``requests/<scenario>/`` (``data/robots/mbm_panda``). A scene is a MoveIt ``PlanningScene``; a request a
``MotionPlanRequest``: its start state's joint positions and its first goal's joint constraints. The
planning joints are the goal's joints; the robot's other joints stay at the start state's values.

Per problem, ``--mode service``: the fitted robot uploaded and the scene imported as ``--checker
sublevel`` does (below), then one ``Client.plan`` call (the ``Plan`` RPC, docs/planning.md): RRT-Connect,
simplification and every edge certified by conservative advancement on the server, within
``--timeout`` (``--seed``, ``--range``, ``--resolution`` and ``--tolerance`` are its settings; ``--planner``,
``--checker`` and ``--sublevel-motions`` do not apply). ``--request-as text`` (the default) sends the
request file's MotionPlanRequest text as it is; ``typed`` sends the start and goal read here (all the
robot's joints). A solved path is certified; a start or goal in collision makes the problem invalid.

Per problem, ``--mode ompl`` (the default): OMPL (``RealVectorStateSpace`` in the URDF's joint limits,
``SimpleSetup``, the planner, path simplification) with

* ``--checker sublevel``: the fitted robot uploaded (``--robot``; for the Panda's URDF
  ``data/robots/panda/panda.robot.json``, else fitted by ``sublevel robot fit``), the scene imported
  (``Client.import_scene``, deleted afterwards); states by ``Client.check_configurations``, motions by
  ``Client.check_motions`` (conservative advancement: each edge proven free, within ``--tolerance``
  of contact). ``--sublevel-motions lazy`` (the default) samples the edges at ``--resolution`` in one
  ``check_configurations`` call during the search, then certifies the simplified path's edges in one
  ``check_motions`` call and searches again (within the time left) when one fails, so every returned
  path is certified (the search pads the states by ``--search-padding``, 5 mm, so that the simplified
  path keeps clear of the obstacles and certifies at padding 0); ``certified`` certifies every edge the planner tries; ``sampled`` only samples;
* ``--checker coal``: the robots peer's pinocchio + coal checker (``coal_peer.py`` from ``--peer-dir``,
  a checkout of the robots peer, which is not part of this repository; without it a minimal one
  here) on the collision meshes; motions sampled at ``--resolution`` configurations per unit of
  joint-space distance (VAMP's 32), as coal has no certified motion check.

``--verify`` re-checks every returned path on pinocchio + coal meshes, each edge densified until the end
effector (``--ee``: panda_hand, else the last link with collision geometry: its frame origin and its
collision geometry's box corners) moves at most ``--verify-step`` (1 mm) between checks, and reports
every path with a colliding state.

Meshes: coal reads the OBJ files through assimp, which joins ``link6.obj``'s faces differently from
the file (data/robots/SOURCE.md); by default the meshes are built from the OBJ files' own vertices
and faces, the surface the fitted robot contains (``--mesh-reader assimp`` keeps coal's reading).

Prints per problem: scenario, scene, solved, planning time, simplification time, states and motions
checked; then per scenario: solved %, median planning time. ``--json OUT`` writes ``{"mode", "joint_names":
[...], "problems": [{"scenario", "scene", "request", "valid_problem", "solved", "certified",
"planning_time_s", "simplify_time_s", "states_checked", "motions_checked", "path": [[...], ...]}, ...]}``
(radians, meters, seconds; the path after simplification, in ``joint_names`` order). With ``--mode
service``: ``planning_time_s`` is the ``Plan`` call's wall time as the client sees it, ``path`` the path
it returned (also an uncertified one when it timed out), ``motions_checked`` the edges sampled plus the
edges certified; each record adds ``status``, ``message``, ``server_time_s`` (the server's time for the
call), the stage times ``goals_time_s``, ``search_time_s``, ``simplify_time_s`` and ``certify_time_s``,
and ``edges_certified``, ``advancement_steps``, ``nodes``, ``repaired`` (``paths_rejected`` is 0: the
service repairs edges instead of rejecting paths).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from mbm_coal import Counts, MeshChecker, Verifier, _peer, van_der_corput

REPO = Path(__file__).resolve().parents[3]
PANDA_ROBOT = REPO / "data" / "robots" / "panda" / "panda.robot.json"


# -- the robot ------------------------------------------------------------------------------------
@dataclass
class Joint:
    """A moving joint of the URDF: its limits (radians or meters; continuous: ±π for sampling)."""

    name: str
    kind: str
    lower: float
    upper: float


def urdf_joints(urdf: Path):
    """The robot's name and its moving, non-mimic joints in URDF order."""
    root = ET.parse(urdf).getroot()
    joints = []
    for j in root.iter("joint"):
        kind = j.get("type")
        if kind not in ("revolute", "continuous", "prismatic") or j.find("mimic") is not None:
            continue
        lim = j.find("limit")
        if kind == "continuous":
            lo, hi = -math.pi, math.pi
        else:
            if lim is None:
                raise ValueError(f"{urdf}: joint {j.get('name')} has no <limit>")
            lo, hi = float(lim.get("lower", 0.0)), float(lim.get("upper", 0.0))
        joints.append(Joint(j.get("name"), kind, lo, hi))
    return root.get("name", ""), joints


def srdf_disabled(srdf: Optional[Path]):
    """The SRDF's ``disable_collisions`` link pairs (as frozensets)."""
    if srdf is None:
        return set()
    return {frozenset((d.get("link1"), d.get("link2"))) for d in ET.parse(srdf).getroot().iter("disable_collisions")}


# -- the problems ---------------------------------------------------------------------------------
@dataclass
class Problem:
    """One planning problem: the scene and request files' names and texts."""

    scenario: str
    index: int
    scene_name: str
    scene: bytes
    request_name: str
    request: bytes


_SCENE = re.compile(r"^scene(\d+)\.ya?ml$")


def _scenario(folder: str, robot: str) -> str:
    return folder[: -len(robot) - 1] if robot and folder.endswith("_" + robot) else folder


def load_problems(source: Path, robot: str, scenarios: Optional[Sequence[str]], limit: int) -> List[Problem]:
    """The problems of ``source`` (a tar, or a folder in either layout), the first ``limit`` of each
    scenario by number (0: all), the scenarios in ``scenarios`` (names with or without the
    ``_<robot>`` suffix) or all of them."""
    files: Dict[str, bytes] = {}
    if source.is_file():
        with tarfile.open(source, "r:*") as tar:
            for m in tar.getmembers():
                if m.isfile() and m.name.endswith((".yaml", ".yml")):
                    files[m.name] = tar.extractfile(m).read()
    elif source.is_dir():
        for p in source.rglob("*.y*ml"):
            files[p.relative_to(source).as_posix()] = p.read_bytes()
    else:
        raise FileNotFoundError(f"--problems {source}: no such file or folder")
    found: Dict[str, List[Problem]] = {}
    for name, data in files.items():
        parts = name.split("/")
        m = _SCENE.match(parts[-1])
        if not m or len(parts) < 2:
            continue
        index, folder = int(m.group(1)), parts[-2]
        candidates = ["/".join(parts[:-1] + [f"request{m.group(1)}.yaml"])]
        if len(parts) >= 3 and parts[-3] == "scenes":  # scenes/<scenario>/ beside requests/<scenario>/
            candidates.append("/".join(parts[:-3] + ["requests", folder, f"request{m.group(1)}.yaml"]))
        request = next((c for c in candidates if c in files), None)
        if request is None:
            print(f"warning: {name} has no request ({' or '.join(candidates)}); skipped", file=sys.stderr)
            continue
        scenario = _scenario(folder, robot)
        found.setdefault(scenario, []).append(
            Problem(scenario, index, parts[-1], data, request.split("/")[-1], files[request])
        )
    if scenarios:
        wanted = {_scenario(s, robot) for s in scenarios}
        missing = wanted - set(found)
        if missing:
            raise ValueError(f"--scenarios: {sorted(missing)} not in {source} (found {sorted(found)})")
        found = {s: p for s, p in found.items() if s in wanted}
    out = []
    for s in sorted(found):
        probs = sorted(found[s], key=lambda p: p.index)
        out += probs[:limit] if limit > 0 else probs
    return out


# MoveIt's default ``start_state_max_bounds_error``: a start value this far (radians, meters) past its
# limit is planned from the limit (FixStartStateBounds), as the service's ``Plan`` does; a goal
# constraint this far past it is taken at the limit (MoveIt's JointConstraint).
BOUNDS_ERROR = 0.05


def into_limits(q: np.ndarray, joints: List[Joint], what: str) -> np.ndarray:
    """``q`` with each value at most :data:`BOUNDS_ERROR` past its joint's limits moved onto them, as
    MoveIt moves a start state and a goal constraint before OMPL sees them (OMPL skips a start or a
    goal outside its state space's bounds); a line on stderr per value moved by more than rounding.
    ValueError for a value farther out."""
    out = q.copy()
    for k, j in enumerate(joints):
        if j.kind == "continuous":
            continue
        v = float(np.clip(q[k], j.lower, j.upper))
        if abs(v - q[k]) > BOUNDS_ERROR:
            raise ValueError(f"{what}: joint {j.name} at {q[k]} is outside its limits [{j.lower}, {j.upper}]")
        if abs(v - q[k]) > 1e-9 * max(1.0, abs(v)):
            print(f"  {what}: joint {j.name} at {q[k]} moved onto its limit {v}", file=sys.stderr)
        out[k] = v
    return out


def read_request(text: bytes, joints: List[Joint]):
    """(planning joint indices, start, goal): the start state's positions of every joint (radians,
    meters) and the goal, whose joint constraints name the planning joints; values up to
    :data:`BOUNDS_ERROR` past a limit moved onto it (:func:`into_limits`)."""
    import yaml

    req = yaml.safe_load(text)
    js = (req.get("start_state") or {}).get("joint_state") or {}
    start_by_name = dict(zip(js.get("name", []), js.get("position", [])))
    goals = req.get("goal_constraints") or []
    if not goals or not goals[0].get("joint_constraints"):
        raise ValueError("the request has no joint-space goal (goal_constraints[0].joint_constraints)")
    goal_by_name = {c["joint_name"]: float(c["position"]) for c in goals[0]["joint_constraints"]}
    names = [j.name for j in joints]
    unknown = sorted(set(goal_by_name) - set(names))
    if unknown:
        raise ValueError(f"goal joints {unknown} are not moving joints of the URDF")
    missing = [n for n in names if n not in start_by_name]
    if missing:
        raise ValueError(f"the start state lacks joints {missing}")
    start = np.array([float(start_by_name[n]) for n in names])
    goal = start.copy()
    for k, n in enumerate(names):
        if n in goal_by_name:
            goal[k] = goal_by_name[n]
    plan = [k for k, n in enumerate(names) if n in goal_by_name]
    return plan, into_limits(start, joints, "start"), into_limits(goal, joints, "goal")


# -- checkers -------------------------------------------------------------------------------------
class SublevelChecker:
    """States and motions checked by the service, in an imported planning scene."""

    def __init__(
        self,
        client,
        robot_id: str,
        joint_names: List[str],
        motions: str,
        resolution: float,
        tolerance: float,
        search_padding: float = 0.0,
    ):
        self.client = client
        self.padding = search_padding
        self.robot = robot_id
        self.names = joint_names
        self.motions = motions
        self.resolution = resolution
        self.tolerance = tolerance
        self.scene = ""
        self.count = Counts()

    def set_scene(self, problem: Problem) -> None:
        self.scene = self.client.import_scene(problem.scene, name=f"plan_mbm {problem.scenario} {problem.scene_name}").scene_id

    def clear_scene(self) -> None:
        if self.scene:
            self.client.delete_scene(self.scene)
            self.scene = ""

    def valid(self, q: np.ndarray) -> bool:
        t0 = time.perf_counter()
        r = self.client.check_configurations(
            self.robot, q, scene=self.scene, joint_names=self.names, padding=self.padding
        )
        self.count.seconds += time.perf_counter() - t0
        self.count.states += 1
        return not bool(r.collides[0])

    def certify(self, path: List[np.ndarray]) -> bool:
        """Whether every edge of `path` is proven free (one ``check_motions`` call)."""
        if len(path) < 2:
            return True
        t0 = time.perf_counter()
        q = np.asarray(path)
        r = self.client.check_motions(
            self.robot, q[:-1], q[1:], scene=self.scene, joint_names=self.names, tolerance=self.tolerance
        )
        self.count.seconds += time.perf_counter() - t0
        self.count.motions += len(path) - 1
        return bool(r.valid.all())

    def motion(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        t0 = time.perf_counter()
        if self.motions == "certified":
            r = self.client.check_motions(
                self.robot, q0, q1, scene=self.scene, joint_names=self.names, tolerance=self.tolerance
            )
            ok = bool(r.valid[0])
        else:
            # The samples in van der Corput order, the check stopping at the first collision (as
            # OMPL's discrete motion validator and the coal checker here do).
            n = max(1, math.ceil(float(np.linalg.norm(q1 - q0)) * self.resolution))
            ts = np.asarray(van_der_corput(n), dtype=float) / n
            r = self.client.check_configurations(
                self.robot,
                q0 + ts[:, None] * (q1 - q0),
                scene=self.scene,
                joint_names=self.names,
                padding=self.padding,
                stop_at_first_collision=True,
            )
            ok = not r.collides.any()
        self.count.seconds += time.perf_counter() - t0
        self.count.motions += 1
        return ok


def plan_one(args, checker, joints: List[Joint], plan_idx: List[int], start: np.ndarray, goal: np.ndarray):
    """One OMPL run: (solved, planning seconds, simplification seconds, path (states, all joints))."""
    from ompl import base as ob
    from ompl import geometric as og

    dof = len(plan_idx)
    space = ob.RealVectorStateSpace(dof)
    bounds = ob.RealVectorBounds(dof)
    for k, j in enumerate(plan_idx):
        bounds.setLow(k, joints[j].lower)
        bounds.setHigh(k, joints[j].upper)
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)
    si = ss.getSpaceInformation()

    def full(state) -> np.ndarray:
        q = start.copy()
        q[plan_idx] = [state[k] for k in range(dof)]
        return q

    ss.setStateValidityChecker(lambda s: bool(checker.valid(full(s))))

    class Motions(ob.MotionValidator):
        def checkMotion(self, s1, s2):  # noqa: N802 (OMPL's name)
            return bool(checker.motion(full(s1), full(s2)))

    motions = Motions(si)  # kept alive while OMPL holds it
    si.setMotionValidator(motions)
    s0, s1 = space.allocState(), space.allocState()
    for k, j in enumerate(plan_idx):
        s0[k], s1[k] = float(start[j]), float(goal[j])
    ss.setStartAndGoalStates(s0, s1)
    planner = getattr(og, args.planner)(si)
    if args.range is not None:
        planner.setRange(args.range)
    ss.setPlanner(planner)
    ss.setup()
    if hasattr(planner, "getRange"):
        args.used_range = planner.getRange()
    # Lazy certification: edges sampled during the search, then the simplified path's edges
    # certified in one call; a path that fails is dropped and the search starts again within the
    # time left. The certification counts as planning time, the simplification does not.
    lazy = getattr(checker, "motions", "") == "lazy"
    planning = simplify = 0.0
    while True:
        ss.solve(max(args.timeout - planning, 1e-3))
        planning += ss.getLastPlanComputationTime()
        if not ss.haveExactSolutionPath():
            return False, planning, simplify, []
        t0 = time.perf_counter()
        ss.simplifySolution(args.simplify_timeout if args.simplify_timeout is not None else args.timeout)
        simplify += time.perf_counter() - t0
        path = ss.getSolutionPath()
        states = [full(path.getState(k)) for k in range(path.getStateCount())]
        if not lazy:
            break
        t0 = time.perf_counter()
        certified = checker.certify(states)
        planning += time.perf_counter() - t0
        if certified:
            break
        checker.count.rejected += 1
        if planning >= args.timeout:
            return False, planning, simplify, []
        ss.clear()
    del motions
    return True, planning, simplify, states


def plan_ompl(args, checker, joints: List[Joint], plan_idx: List[int], start: np.ndarray, goal: np.ndarray,
              problem: Problem) -> dict:
    """One problem planned by OMPL with ``checker`` (``--mode ompl``): its record, as ``--json``
    writes it."""
    before_s, before_m = checker.count.states, checker.count.motions
    before_r = getattr(checker.count, "rejected", 0)
    # Start and goal are judged unpadded; when either lies within the search padding, the problem
    # is searched without it (OMPL refuses an invalid start).
    search_padding = getattr(checker, "padding", 0.0)
    checker.padding = 0.0
    start_ok, goal_ok = checker.valid(start), checker.valid(goal)
    if search_padding and start_ok and goal_ok:
        checker.padding = search_padding
        if not (checker.valid(start) and checker.valid(goal)):
            checker.padding = 0.0
    if start_ok and goal_ok:
        solved, planning, simplify, path = plan_one(args, checker, joints, plan_idx, start, goal)
    else:
        solved, planning, simplify, path = False, 0.0, 0.0, []
    checker.padding = search_padding
    # Certified: the sublevel checker's lazy and certified motions prove every returned edge free.
    certifies = isinstance(checker, SublevelChecker) and checker.motions in ("lazy", "certified")
    return {
        "scenario": problem.scenario,
        "scene": problem.scene_name,
        "request": problem.request_name,
        "valid_problem": bool(start_ok and goal_ok),
        "solved": solved,
        "certified": bool(solved and certifies),
        "planning_time_s": planning,
        "simplify_time_s": simplify,
        "states_checked": checker.count.states - before_s,
        "motions_checked": checker.count.motions - before_m,
        "paths_rejected": checker.count.rejected - before_r,
        "path": [[float(v) for v in q] for q in path],
    }


def plan_service(args, client, robot_id: str, scene: str, problem: Problem, joints: List[Joint]) -> dict:
    """One ``Plan`` call (``--mode service``): the problem's record, as ``--json`` writes it (the
    path in the URDF's joint order)."""
    names = [j.name for j in joints]
    settings = dict(timeout=args.timeout, seed=args.seed, range=args.range, resolution=args.resolution,
                    tolerance=args.tolerance)
    t0 = time.perf_counter()
    if args.request_as == "text":
        r = client.plan(robot_id, scene=scene, motion_plan_request=problem.request.decode("utf-8"), **settings)
    else:
        _, start, goal = read_request(problem.request, joints)
        r = client.plan(robot_id, scene=scene, start=start, goal=goal, joint_names=names, **settings)
    wall = time.perf_counter() - t0
    columns = [r.joint_names.index(n) for n in names]
    path = r.path[:, columns]
    return {
        "scenario": problem.scenario,
        "scene": problem.scene_name,
        "request": problem.request_name,
        "valid_problem": r.status not in ("start_in_collision", "goal_in_collision"),
        "solved": r.solved,
        "certified": r.certified,
        "status": r.status,
        "message": r.message,
        "planning_time_s": wall,
        "server_time_s": r.timing["total"],
        "goals_time_s": r.timing["goals"],
        "search_time_s": r.timing["search"],
        "simplify_time_s": r.timing["simplify"],
        "certify_time_s": r.timing["certify"],
        "states_checked": r.states_checked,
        "motions_checked": r.edges_checked + r.edges_certified,
        "edges_certified": r.edges_certified,
        "advancement_steps": r.advancement_steps,
        "nodes": r.nodes,
        "repaired": r.repaired,
        "paths_rejected": 0,
        "path": [[float(v) for v in q] for q in path],
    }


def find_binary(explicit: Optional[str]) -> Path:
    """The sublevel binary: ``explicit``, else on PATH, else the newer of target/{release,debug}."""
    if explicit:
        if not Path(explicit).is_file():
            raise FileNotFoundError(f"--sublevel-bin {explicit}: no such file")
        return Path(explicit)
    on_path = shutil.which("sublevel")
    if on_path:
        return Path(on_path)
    built = [p for p in (REPO / "target" / "release" / "sublevel", REPO / "target" / "debug" / "sublevel") if p.is_file()]
    if not built:
        raise FileNotFoundError("no sublevel binary: pass --sublevel-bin, put it on PATH, or `cargo build --release`")
    return max(built, key=lambda p: p.stat().st_mtime)


def fitted_robot(args, urdf_text: str) -> Path:
    """The fitted robot file: --robot if it exists, the Panda's when the URDF is its, else
    ``sublevel robot fit`` into --robot (or a temporary folder)."""
    if args.robot and Path(args.robot).is_file():
        return Path(args.robot)
    if not args.robot and PANDA_ROBOT.is_file():
        with open(PANDA_ROBOT, encoding="utf-8") as f:
            if json.load(f).get("urdf") == urdf_text:
                return PANDA_ROBOT
    out = Path(args.robot) if args.robot else Path(tempfile.mkdtemp(prefix="plan_mbm-")) / "robot.json"
    cmd = [str(find_binary(args.sublevel_bin)), "robot", "fit", str(args.urdf), "--output", str(out)]
    if args.srdf:
        cmd += ["--srdf", str(args.srdf)]
    for d in args.package_dir or [args.urdf.parent]:
        cmd += ["--package-dir", str(d)]
    print("fitting the robot (once; link meshes are cached): " + " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)  # its progress goes to our stderr
    return out


@contextlib.contextmanager
def served(args):
    """The server's address: --addr, or with --serve a server started for the run."""
    if not args.serve:
        yield args.addr
        return
    binary = find_binary(args.sublevel_bin)
    data = tempfile.mkdtemp(prefix="plan_mbm-store-")
    proc = subprocess.Popen(
        [str(binary), "serve", "--addr", "127.0.0.1:0", "--data-dir", data],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL, text=True,
    )
    try:
        addr = None
        deadline = time.monotonic() + 60
        while addr is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            m = re.match(r"listening on (\S+)", line)
            addr = m.group(1) if m else None
        if addr is None:
            raise RuntimeError(f"{binary} serve printed no `listening on` line")
        print(f"server {binary} on {addr}", flush=True)
        yield addr
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        shutil.rmtree(data, ignore_errors=True)


def median(v):
    return statistics.median(v) if v else float("nan")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--urdf", type=Path, required=True, help="the robot's URDF")
    ap.add_argument("--srdf", type=Path, help="its SRDF (disabled collision pairs)")
    ap.add_argument("--package-dir", type=Path, action="append",
                    help="where package://NAME/PATH meshes resolve as DIR/NAME/PATH (repeatable; default: the URDF's folder)")
    ap.add_argument("--robot", help="the fitted robot file (sublevel robot fit); fitted into this path when it does not exist")
    ap.add_argument("--problems", type=Path, required=True, help="MotionBenchMaker problems: a tar or a folder")
    ap.add_argument("--scenarios", nargs="+", help="scenarios to plan (default: all)")
    ap.add_argument("--limit", type=int, default=0, help="the first N problems of each scenario (default: all)")
    ap.add_argument("--timeout", type=float, default=1.0, help="planning time limit per problem, seconds (default 1)")
    ap.add_argument("--simplify-timeout", type=float, help="path simplification time limit, seconds (default: --timeout)")
    ap.add_argument("--mode", choices=("ompl", "service"), default="ompl",
                    help="plan with OMPL here, its checks by --checker (ompl, default), or with the service's "
                         "Plan RPC, one call per problem (service)")
    ap.add_argument("--request-as", choices=("text", "typed"), default="text",
                    help="service mode: send the request file's MotionPlanRequest text (text, default) or the start "
                         "and goal read here (typed)")
    ap.add_argument("--planner", default="RRTConnect", help="an OMPL geometric planner (default RRTConnect)")
    ap.add_argument("--range", type=float,
                    help="the planner's range (joint-space distance; default: OMPL's, or the service's 1.0)")
    ap.add_argument("--seed", type=int, default=1, help="OMPL's random seed, or the Plan call's seed (default 1)")
    ap.add_argument("--checker", choices=("sublevel", "coal"), default="sublevel", help="collision checker (default sublevel)")
    ap.add_argument("--addr", default="127.0.0.1:50051", help="the Sublevel server (default 127.0.0.1:50051)")
    ap.add_argument("--serve", action="store_true", help="start a server (sublevel serve, a temporary store) for the run")
    ap.add_argument("--sublevel-bin", help="the sublevel binary (default: PATH, else target/release or target/debug)")
    ap.add_argument("--sublevel-motions", choices=("lazy", "certified", "sampled"), default="lazy",
                    help="sublevel: edges sampled at --resolution during the search and the final path certified, "
                         "replanning if it fails (lazy, default); every edge certified by conservative advancement "
                         "(certified); or sampled only (sampled)")
    ap.add_argument("--tolerance", type=float, default=1e-3, help="sublevel certified motions: contact tolerance, meters (default 0.001)")
    ap.add_argument("--resolution", type=float, default=32.0,
                    help="sampled motions: configurations per unit of joint-space distance (default 32, VAMP's)")
    ap.add_argument("--search-padding", type=float, default=0.005,
                    help="sublevel lazy motions: padding of the sampled states during the search, meters "
                         "(default 0.005): a path kept clear of the obstacles is certified at padding 0 in "
                         "fewer advancement steps, where a path simplified against them is often refused "
                         "within the contact tolerance and searched again")
    ap.add_argument("--peer-dir", type=Path,
                    help="a checkout of the robots peer, whose coal_peer.py loads the scenes for the coal checker "
                         "and --verify (default: none, a minimal loader here)")
    ap.add_argument("--mesh-reader", choices=("obj", "assimp"), default="obj",
                    help="coal meshes from the OBJ files' own faces (default) or coal's assimp reading")
    ap.add_argument("--verify", action="store_true", help="re-check every path on the meshes at --verify-step of end-effector travel")
    ap.add_argument("--verify-step", type=float, default=1e-3, help="end-effector travel between verified states, meters (default 0.001)")
    ap.add_argument("--ee", help="the end-effector link for --verify (default panda_hand, else the last link with geometry)")
    ap.add_argument("--json", type=Path, help="write the problems, paths and figures here")
    args = ap.parse_args(argv)
    service = args.mode == "service"
    if service and args.checker != "sublevel":
        ap.error("--mode service plans on the service: --checker coal does not apply (use --verify for coal)")
    if not service:
        from ompl import util as ou

        ou.setLogLevel(ou.LOG_ERROR)
        ou.RNG.setSeed(args.seed)

    urdf_text = args.urdf.read_text()
    robot_name, joints = urdf_joints(args.urdf)
    names = [j.name for j in joints]
    problems = load_problems(args.problems, robot_name, args.scenarios, args.limit)
    if not problems:
        print(f"no problems in {args.problems}", file=sys.stderr)
        return 2
    package_dir = (args.package_dir or [args.urdf.parent])[0]
    disabled = srdf_disabled(args.srdf)
    peer = _peer(args.peer_dir) if (args.checker == "coal" or args.verify) else None
    mesh = None
    if args.checker == "coal" or args.verify:
        mesh = MeshChecker(args.urdf, package_dir, names, disabled, peer, args.mesh_reader == "obj", args.resolution)
    verifier = Verifier(mesh, args.ee, args.verify_step) if args.verify else None
    if service:
        how = f"mode service (one Plan call per problem, the request sent {args.request_as})"
    else:
        how = f"checker {args.checker}" + (
            f" (motions {args.sublevel_motions})" if args.checker == "sublevel"
            else f" (motions sampled at {args.resolution:g}/rad)"
        ) + f", {args.planner}"
    print(
        f"{len(problems)} problems, {how}, timeout {args.timeout:g} s"
        + (f"; coal from {'the peer' if peer else 'the minimal loader'}, meshes read by {args.mesh_reader}" if mesh else "")
        + (f"; verify at {args.verify_step * 1e3:g} mm of {verifier.ee}" if verifier else ""),
        flush=True,
    )

    with contextlib.ExitStack() as stack:
        if args.checker == "sublevel":
            from sublevel_client import Client

            addr = stack.enter_context(served(args))
            client = stack.enter_context(Client(addr, timeout=600.0))
            client.wait_ready(10.0)
            robot_file = fitted_robot(args, urdf_text)
            info = client.upload_robot(robot_file)
            stack.callback(client.delete_robot, info.robot_id)
            if set(info.joint_names) != set(names):
                raise SystemExit(f"the fitted robot's joints {info.joint_names} are not the URDF's {names}")
            print(f"robot {info.name} ({info.robot_id}) from {robot_file}: {info.dof} joints, {info.geometries} geometries, "
                  f"{info.self_pairs} self pairs", flush=True)
            checker = None if service else SublevelChecker(
                client,
                info.robot_id,
                names,
                args.sublevel_motions,
                args.resolution,
                args.tolerance,
                args.search_padding if args.sublevel_motions == "lazy" else 0.0,
            )
        else:
            checker = mesh

        results = []
        header = f"{'scenario':<18} {'scene':<14} {'solved':<7} {'plan ms':>9} {'simplify ms':>11} {'states':>8} {'motions':>8}"
        print(header + ("  verify" if verifier else ""), flush=True)
        for p in problems:
            if service:
                scene = client.import_scene(p.scene, name=f"plan_mbm {p.scenario} {p.scene_name}").scene_id
            else:
                plan_idx, start, goal = read_request(p.request, joints)
                checker.set_scene(p)
            if mesh is not None and mesh is not checker:
                mesh.set_scene(p)
            try:
                if service:
                    row = plan_service(args, client, info.robot_id, scene, p, joints)
                else:
                    row = plan_ompl(args, checker, joints, plan_idx, start, goal, p)
                solved, path = row["solved"], [np.asarray(q) for q in row["path"]]
                note = "" if row["valid_problem"] else "  (start or goal in collision)"
                if service and row["status"] == "timed_out":
                    note = "  (timed out" + (f", {len(path)} waypoints not all certified)" if path else ")")
                if verifier is not None and solved:
                    n, hit = verifier.check_path(path)
                    row["verify_states"] = n
                    row["verify_collision"] = None if hit is None else {"edge": hit[0], "t": hit[1]}
                    note = f"  {n} states, " + ("free" if hit is None else f"COLLIDES at edge {hit[0]} t={hit[1]:.6f}")
            finally:
                if service:
                    client.delete_scene(scene)
                else:
                    checker.clear_scene()
                if mesh is not None and mesh is not checker:
                    mesh.clear_scene()
            results.append(row)
            print(
                f"{p.scenario:<18} {p.scene_name:<14} {str(solved):<7} {row['planning_time_s'] * 1e3:9.1f} "
                f"{row['simplify_time_s'] * 1e3:11.1f} {row['states_checked']:8d} {row['motions_checked']:8d}{note}",
                flush=True,
            )

    print()
    used_range = getattr(args, "used_range", None)
    if service:
        used_range = args.range if args.range is not None else 1.0  # the Plan call's default range
        print(f"mode service (Plan, the request sent {args.request_as}, range {used_range:.3g})"
              f", timeout {args.timeout:g} s, seed {args.seed}:")
    else:
        print(f"checker {args.checker}" + (f" (motions {args.sublevel_motions})" if args.checker == "sublevel" else "")
              + f", {args.planner}" + (f" (range {used_range:.3g})" if used_range else "")
              + f", timeout {args.timeout:g} s, seed {args.seed}:")
    cols = "| scenario | problems | valid | solved | solved % | median planning time (ms) | median states | median motions |"
    sep = "|---|---|---|---|---|---|---|---|"
    if verifier:
        cols += " paths colliding at 1 mm |" if args.verify_step == 1e-3 else f" paths colliding at {args.verify_step * 1e3:g} mm |"
        sep += "---|"
    print(cols)
    print(sep)
    for s in sorted({r["scenario"] for r in results}) + ["all"]:
        rs = [r for r in results if s in ("all", r["scenario"])]
        valid = [r for r in rs if r["valid_problem"]]
        solved = [r for r in valid if r["solved"]]
        line = (
            f"| {s} | {len(rs)} | {len(valid)} | {len(solved)} | {100.0 * len(solved) / max(len(valid), 1):.0f} | "
            f"{median([r['planning_time_s'] * 1e3 for r in solved]):.1f} | "
            f"{median([r['states_checked'] for r in solved]):.0f} | {median([r['motions_checked'] for r in solved]):.0f} |"
        )
        if verifier:
            line += f" {sum(r.get('verify_collision') is not None for r in solved)} of {len(solved)} |"
        print(line)

    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        with open(args.json, "w") as f:
            json.dump({"mode": args.mode, "joint_names": names, "checker": args.checker,
                       "planner": "Plan (RRT-Connect, certified)" if service else args.planner,
                       "range": used_range, "timeout_s": args.timeout, "problems": results}, f, indent=1)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # OMPL's nanobind module reports leaked bindings at interpreter exit; skip that noise.
    os._exit(code)
