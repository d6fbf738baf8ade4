#!/usr/bin/env python3
"""Plan the MotionBenchMaker problems with a timed trajectory (``Client.plan(..., trajectory=True)``),
check every trajectory independently, and time the same geometric paths with ``toppra``.

    python clients/python/examples/trajectory_mbm.py --problems data/robots/mbm_panda \\
        --joint-limits data/robots/panda/joint_limits.yaml [--limit 10] [--serve] [--toppra] \\
        [--json out/trajectory_mbm.json]

Needs ``pip install ./clients/python pyyaml``, and ``toppra`` for ``--toppra``; a running server
(``sublevel serve``; ``--serve`` starts one from the binary for the run, its store in a temporary
folder). Problems and robot as ``plan_mbm.py`` reads them (``--robot``: the fitted robot file; the
Panda's by default).

Per problem:

1. ``Client.plan`` of the request's MotionPlanRequest text with ``trajectory=True`` and the
   ``--joint-limits`` file, points every ``--sample-dt`` (0.01 s): its wall time as the client sees
   it, the server's trajectory stage (``JointTrajectory.seconds``), the duration.
2. ``Client.time_trajectory`` of the same path at 1 ms: the same duration (checked), then the
   checks: it starts and ends at rest on the path's ends; every sample's velocity and acceleration
   within the limits to 1e-6 relative; positions agree with velocities (trapezoid rule within
   ``a·dt²``); every 1 ms sample free by ``Client.check_configurations`` on the collision meshes.
3. ``Client.time_trajectory`` with ``max_deviation=0``: the duration of stopping at every waypoint.
4. With ``--toppra``: toppra (TOPP-RA, Pham and Pham 2018) times the same geometry (the path's
   straight pieces and its blends, rebuilt here from the waypoints and ``corner_deviation``) within
   the same limits: the ratio of the durations.

Prints per scenario: solved, certified trajectories, limit violations, colliding samples, median
duration (blended, stopping, toppra), the median ratio to toppra, the median trajectory stage on the
server and the median wall time of the plan with its trajectory.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import List, Optional

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from plan_mbm import PANDA_ROBOT, load_problems, served  # noqa: E402

from sublevel_client import Client  # noqa: E402

REPO = Path(__file__).resolve().parents[3]


class BlendedPath:
    """The geometry a Sublevel trajectory follows: the waypoints' segments with each corner i
    replaced by a circular arc tangent to both, ``deviation[i]`` from the corner (Kunz and
    Stilman, RSS 2012), parameterized by arc length; as ``toppra``'s ``AbstractGeometricPath``."""

    def __init__(self, waypoints: np.ndarray, deviation: np.ndarray):
        w = np.asarray(waypoints, dtype=float)
        self.pieces = []  # ("line", from, direction, length) or ("arc", center, x, y, radius, angle)
        seg = [(w[i + 1] - w[i]) for i in range(len(w) - 1)]
        lens = [float(np.linalg.norm(d)) for d in seg]
        dirs = [d / n for d, n in zip(seg, lens)]
        cuts = [0.0] * len(w)
        arcs = [None] * len(w)
        for i in range(1, len(w) - 1):
            if deviation[i] <= 0:
                continue
            y1, y2 = dirs[i - 1], dirs[i]
            alpha = float(np.arccos(np.clip(y1 @ y2, -1.0, 1.0)))
            half = alpha / 2
            # The deviation given is the one taken: ℓ from it directly.
            radius = deviation[i] * np.cos(half) / (1 - np.cos(half))
            ell = radius * np.tan(half)
            bis = (y2 - y1) / np.linalg.norm(y2 - y1)
            center = w[i] + bis * radius / np.cos(half)
            start = w[i] - ell * y1
            arcs[i] = ("arc", center, (start - center) / radius, y1, radius, alpha)
            cuts[i] = ell
        for i in range(len(w) - 1):
            length = lens[i] - cuts[i] - cuts[i + 1]
            if length > 1e-12 * max(lens[i], 1.0):
                self.pieces.append(("line", w[i] + cuts[i] * dirs[i], dirs[i], length))
            if i + 1 < len(w) and arcs[i + 1] is not None:
                self.pieces.append(arcs[i + 1])
        self.lengths = np.array([p[3] if p[0] == "line" else p[4] * p[5] for p in self.pieces])
        self.starts = np.concatenate([[0.0], np.cumsum(self.lengths)[:-1]])
        self.total = float(self.lengths.sum())
        self.n = w.shape[1]

    def __call__(self, ss, order=0):
        scalar = np.isscalar(ss)
        ss = np.atleast_1d(np.asarray(ss, dtype=float))
        out = np.zeros((len(ss), self.n))
        idx = np.clip(np.searchsorted(self.starts, ss, side="right") - 1, 0, len(self.pieces) - 1)
        for k, (s, i) in enumerate(zip(ss, idx)):
            p = self.pieces[i]
            u = min(max(s - self.starts[i], 0.0), self.lengths[i])
            if p[0] == "line":
                out[k] = p[1] + u * p[2] if order == 0 else (p[2] if order == 1 else 0.0)
            else:
                _, c, x, y, r, _ = p
                sin, cos = np.sin(u / r), np.cos(u / r)
                if order == 0:
                    out[k] = c + r * (x * cos + y * sin)
                elif order == 1:
                    out[k] = -x * sin + y * cos
                else:
                    out[k] = -(x * cos + y * sin) / r
        return out[0] if scalar else out

    @property
    def dof(self):
        return self.n

    @property
    def path_interval(self):
        return np.array([0.0, self.total])

    @property
    def waypoints(self):
        return None


def toppra_duration(path: BlendedPath, vmax: np.ndarray, amax: np.ndarray) -> float:
    """toppra's time-optimal duration of ``path`` within the limits, at rest at both ends, on a
    grid of stations 0.01 apart plus every piece boundary (the grid Sublevel's timing uses)."""
    import toppra as ta
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    grid = [0.0]
    for start, length in zip(path.starts, path.lengths):
        count = max(int(np.ceil(length / 0.01)), 1)
        grid.extend(start + length * np.arange(1, count + 1) / count)
    grid[-1] = path.total
    vlim = np.stack([-vmax, vmax], axis=1)
    alim = np.stack([-amax, amax], axis=1)
    instance = algo.TOPPRA(
        [constraint.JointVelocityConstraint(vlim),
         constraint.JointAccelerationConstraint(alim, discretization_scheme=constraint.DiscretizationType.Interpolation)],
        path, gridpoints=np.array(grid), parametrizer="ParametrizeConstAccel",
    )
    traj = instance.compute_trajectory(0, 0)
    if traj is None:
        return float("nan")
    return float(traj.duration)


def check(tr, path: np.ndarray) -> dict:
    """The checks of a 1 ms trajectory (module docs), as counts."""
    v, a = tr.max_velocity, tr.max_acceleration
    dt = np.diff(tr.t)[:, None]
    moved = np.diff(tr.q, axis=0)
    predicted = (tr.qd[1:] + tr.qd[:-1]) / 2 * dt
    return {
        "at_rest": bool(not tr.qd[0].any() and not tr.qd[-1].any()),
        "on_ends": bool(np.array_equal(tr.q[0], path[0]) and np.array_equal(tr.q[-1], path[-1])),
        "velocity_violations": int(np.sum(np.abs(tr.qd) > v * (1 + 1e-6))),
        "acceleration_violations": int(np.sum(np.abs(tr.qdd) > a * (1 + 1e-6))),
        "integration_errors": int(np.sum(np.abs(moved - predicted) > a * dt * dt)),
    }


def median(v):
    v = [x for x in v if x == x]
    return statistics.median(v) if v else float("nan")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", type=Path, default=REPO / "data" / "robots" / "mbm_panda")
    ap.add_argument("--robot-name", default="panda", help="the robot's name in MotionBenchMaker folder names")
    ap.add_argument("--robot", type=Path, default=PANDA_ROBOT, help="the fitted robot file")
    ap.add_argument("--joint-limits", type=Path, help="a MoveIt joint_limits.yaml")
    ap.add_argument("--scenarios", nargs="*", help="only these scenarios")
    ap.add_argument("--limit", type=int, default=0, help="problems per scenario (0: all)")
    ap.add_argument("--timeout", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--sample-dt", type=float, default=0.01, help="seconds between the plan's trajectory points")
    ap.add_argument("--toppra", action="store_true", help="time the same geometry with toppra")
    ap.add_argument("--no-check-samples", action="store_true", help="skip check_configurations of the 1 ms samples")
    ap.add_argument("--addr", default="127.0.0.1:50051")
    ap.add_argument("--serve", action="store_true", help="start a server for the run (--sublevel-bin)")
    ap.add_argument("--sublevel-bin", help="the sublevel binary for --serve")
    ap.add_argument("--json", type=Path, help="write every problem's record here")
    args = ap.parse_args(argv)
    problems = load_problems(args.problems, args.robot_name, args.scenarios, args.limit)
    limits = args.joint_limits.read_text() if args.joint_limits else None
    records: List[dict] = []
    with served(args) as addr:
        client = Client(addr)
        robot = client.upload_robot(args.robot)
        try:
            scenes = {}
            for p in problems:
                key = (p.scenario, p.scene_name)
                if key not in scenes:
                    scenes[key] = client.import_scene(p.scene.decode("utf-8"), name=f"{p.scenario} {p.scene_name}").scene_id
                scene = scenes[key]
                text = p.request.decode("utf-8")
                t0 = time.perf_counter()
                r = client.plan(robot.robot_id, scene=scene, motion_plan_request=text, timeout=args.timeout,
                                seed=args.seed, trajectory=True, joint_limits=limits, sample_dt=args.sample_dt)
                wall = time.perf_counter() - t0
                rec = {"scenario": p.scenario, "scene": p.scene_name, "status": r.status, "solved": r.solved,
                       "wall_s": wall, "server_s": r.timing["total"]}
                try:
                    if r.trajectory is not None:
                        timed_checks(args, client, robot.robot_id, scene, r, rec, limits)
                except Exception as e:  # noqa: BLE001 (a failure is a result of the run)
                    rec["error"] = f"{type(e).__name__}: {e}"
                records.append(rec)
                print(json.dumps({k: (round(v, 6) if isinstance(v, float) else v) for k, v in rec.items()}), flush=True)
        finally:
            for scene in scenes.values():
                client.delete_scene(scene)
            client.delete_robot(robot.robot_id)
    summarize(records)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"problems": records}, indent=1))
    return 0


def timed_checks(args, client, robot_id: str, scene: str, r, rec: dict, limits: Optional[str]) -> None:
    """Steps 2-4 of the module docs for a plan ``r`` with a trajectory, into ``rec``."""
    tr = r.trajectory
    rec.update(certified=tr.certified and r.certified, duration=tr.duration, stage_s=tr.seconds,
               blends=tr.blends, tightened=tr.blends_tightened, stops=tr.stops, waypoints=r.waypoints)
    dense = client.time_trajectory(robot_id, r.path, scene=scene, joint_limits=limits, sample_dt=0.001)
    rec["same_duration"] = abs(dense.duration - tr.duration) <= 1e-9 * tr.duration
    rec.update(check(dense, r.path))
    if not args.no_check_samples:
        answer = client.check_configurations(robot_id, dense.q, scene=scene)
        rec["colliding_samples"] = int(np.sum(answer.collides))
    stop = client.time_trajectory(robot_id, r.path, scene=scene, joint_limits=limits, max_deviation=0.0)
    rec["stop_duration"] = stop.duration
    if args.toppra:
        geometry = BlendedPath(r.path, tr.corner_deviation)
        rec["toppra_duration"] = toppra_duration(geometry, tr.max_velocity, tr.max_acceleration)


def summarize(records: List[dict]) -> None:
    """The table of the module docs, one row per scenario."""
    print()
    header = ("scenario", "solved", "certified", "errors", "v/a viol", "collide", "median s", "stop s", "saved",
              "toppra s", "ratio", "stage ms", "wall ms")
    print(" | ".join(header))
    for scenario in sorted({r["scenario"] for r in records}):
        rs = [r for r in records if r["scenario"] == scenario]
        timed = [r for r in rs if "duration" in r and "error" not in r]
        ratio = [r["duration"] / r["toppra_duration"] for r in timed if r.get("toppra_duration")]
        saved = [1 - r["duration"] / r["stop_duration"] for r in timed]
        row = (
            scenario,
            f"{sum(r['solved'] for r in rs)}/{len(rs)}",
            f"{sum(r['certified'] for r in timed)}",
            f"{sum('error' in r for r in rs)}",
            f"{sum(r['velocity_violations'] + r['acceleration_violations'] for r in timed)}",
            f"{sum(r.get('colliding_samples', 0) for r in timed)}",
            f"{median([r['duration'] for r in timed]):.3f}",
            f"{median([r['stop_duration'] for r in timed]):.3f}",
            f"{100 * median(saved):.1f}%",
            f"{median([r.get('toppra_duration', float('nan')) for r in timed]):.3f}",
            f"{median(ratio):.4f}",
            f"{1e3 * median([r['stage_s'] for r in timed]):.2f}",
            f"{1e3 * median([r['wall_s'] for r in rs]):.2f}",
        )
        print(" | ".join(row))


if __name__ == "__main__":
    sys.exit(main())
