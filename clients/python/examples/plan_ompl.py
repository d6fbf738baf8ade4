#!/usr/bin/env python3
"""Plan the PSB chair through a slalom of PSB obstacles in SE(3) with OMPL, the Sublevel service
as the collision checker.

    python clients/python/examples/plan_ompl.py [--addr 127.0.0.1:50051] [--png out/plan_ompl.png]
        [--max-degree 2|4|6|8] [--time SECONDS] [--seed N]

Needs a running server (``cargo run --release -- serve --demo``) and
``pip install ./clients/python ompl matplotlib`` (matplotlib only for the figure: ``--png ''``
draws none).

What it does:

* loads the chair (``data/demo/chair_101.json``) as the robot and ten fitted PSB bodies
  (``data/demo/chair_101.json``, ``data/demo/human_10.json`` and ``tests/data/SHAPE.degN.json``:
  chair and human, degrees 2 to 8) as obstacles into a fresh scene (deleted at the end unless
  ``--keep``). Bodies are uploaded under names ``plan_ompl/...``; a later run reuses a stored
  body of the same name and identical polynomial (an upload certifies sos-convexity with an SDP:
  ~40 s for degree 8), ``--delete-bodies`` removes the ones it uploaded. The bodies stand upright
  (their y axis turned to world z) in two walls across the x axis with gaps on opposite sides, so the
  path from x = -3.2 m to x = +3.2 m must slalom around them; the robot's height is bounded so
  it cannot pass over or under a wall.
* OMPL (SE3StateSpace, SimpleSetup, RRTConnect) asks the service through one QueryStream:
  - state validity: a plain Python callable sending one request per state with one COLLIDE
    query (margin ``--margin`` m) per obstacle: valid iff none collides;
  - motion validity: a ``MotionValidator`` sending the states along a segment (every
    ``--resolution`` of OMPL's SE(3) distance) as candidate states of one request;
  - clearance of the final path: DISTANCE queries along the interpolated path, one request.
* prints states checked per second, the path's length and waypoints, and draws the path (top and
  side views) to ``--png``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from sublevel_client import Client, Pose, Query, quat_from_axis_angle, quat_multiply

REPO = Path(__file__).resolve().parents[3]

# Body y (the PSB shapes' "up") turned to world z: a quarter turn about x.
UPRIGHT = quat_from_axis_angle((1.0, 0.0, 0.0), math.pi / 2)

START = (-3.2, 0.0, 0.0)
GOAL = (3.2, 0.0, 0.0)
BOUNDS_LOW = (-4.0, -3.4, -0.35)
BOUNDS_HIGH = (4.0, 3.4, 0.35)


# The obstacles: body files of the repository, named one by one (their folders hold other JSON
# files too, such as robots), one per place of the two walls.
OBSTACLE_FILES = ["data/demo/chair_101.json", "data/demo/human_10.json"] + [
    f"tests/data/{shape}.deg{degree}.json" for shape in ("chair_101", "human_10") for degree in (2, 4, 6, 8)
]


def obstacle_files(max_degree=8):
    """The fitted PSB bodies bundled with the repository that stand as obstacles (name, path).
    A body of degree above ``max_degree`` is replaced by the same shape's fit of degree
    ``max_degree`` (``tests/data/SHAPE.degN.json``), at the same place: the walls stay closed and
    every upload certifies a smaller polynomial."""
    out = []
    for f in OBSTACLE_FILES:
        stem = Path(f).name.split(".")
        if len(stem) == 3 and stem[1].startswith("deg") and int(stem[1][3:]) > max_degree:
            f = f"tests/data/{stem[0]}.deg{max_degree}.json"
        out.append((str(Path(f).with_suffix("")), REPO / f))
    return out


def wall_layout(n):
    """Obstacle positions: two walls across the x axis (x = -1.2 m with its gap at y > 1.3 m,
    x = +1.2 m with its gap at y < -1.3 m), 0.85 m apart along y."""
    ys = [-2.6, -1.75, -0.9, -0.05, 0.8]
    places = [(-1.2, y) for y in ys] + [(1.2, -y) for y in ys]
    out = []
    for k in range(n):
        x, y = places[k % len(places)]
        # A turn about the vertical for variety; each body stays upright.
        yaw = quat_from_axis_angle((0.0, 0.0, 1.0), 0.35 * ((k % 3) - 1))
        out.append(Pose(quat=quat_multiply(yaw, UPRIGHT), t=(x, y, 0.0)))
    return out


def body_polynomial(body):
    """p(x) of a body file, vectorized over points x of shape (..., 3) in the body frame (meters)."""
    e = np.asarray(body["exponents"])
    c = np.asarray(body["coefficients"])
    center, scale = np.asarray(body["center"]), float(body["scale"])

    top = int(e.max())

    def p(x):
        u = (np.asarray(x, dtype=float) - center) / scale
        powers = u[..., None] ** np.arange(top + 1)  # (..., 3, top + 1)
        return (powers[..., 0, e[:, 0]] * powers[..., 1, e[:, 1]] * powers[..., 2, e[:, 2]]) @ c

    return p


def boundary_points(body, n_dirs=1200):
    """Body-frame points on the boundary {p = 1} (meters), by bisection along rays from an
    interior point (the set is convex, so every ray leaves it once). For drawing."""
    p = body_polynomial(body)
    center, scale = np.asarray(body["center"]), float(body["scale"])
    g = np.linspace(-2.0, 2.0, 17)
    grid = center + scale * np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    x0 = grid[p(grid) <= 1.0].mean(axis=0)  # a mean of points of a convex set lies in it
    k = np.arange(n_dirs) + 0.5  # a Fibonacci sphere of directions
    phi = np.arccos(1.0 - 2.0 * k / n_dirs)
    theta = np.pi * (1.0 + 5.0**0.5) * k
    d = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], -1)
    lo, hi = np.zeros(n_dirs), np.full(n_dirs, scale)
    for _ in range(60):
        out = p(x0 + hi[:, None] * d) > 1.0
        if out.all():
            break
        hi[~out] *= 2.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        inside = p(x0 + mid[:, None] * d) <= 1.0
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    return x0 + lo[:, None] * d


def hull2d(pts):
    """Convex hull of 2-D points (Andrew's monotone chain), closed polygon (m, 2)."""
    pts = sorted(map(tuple, np.round(pts, 12)))

    def half(points):
        h = []
        for q in points:
            while len(h) >= 2 and (h[-1][0] - h[-2][0]) * (q[1] - h[-2][1]) - (h[-1][1] - h[-2][1]) * (q[0] - h[-2][0]) <= 0:
                h.pop()
            h.append(q)
        return h

    lower, upper = half(pts), half(pts[::-1])
    poly = lower[:-1] + upper[:-1]
    return np.array(poly + poly[:1])


class ServiceChecker:
    """OMPL's collision checking through one QueryStream of the service."""

    def __init__(self, stream, robot, obstacles, margin, space):
        self.stream = stream
        self.robot = robot
        self.space = space
        self.collide = [Query.collide(robot, o, margin) for o in obstacles]
        self.states = 0
        self.seconds = 0.0
        self.motion_states = 0
        self.motion_segments = 0
        self.motion_seconds = 0.0

    @staticmethod
    def pose(state):
        r = state.rotation()
        return Pose(quat=(r.w, r.x, r.y, r.z), t=(state.getX(), state.getY(), state.getZ()))

    def is_valid(self, state) -> bool:
        """State validity: one request, one COLLIDE query per obstacle."""
        t0 = time.perf_counter()
        answers = self.stream.check(poses={self.robot: self.pose(state)}, queries=self.collide)
        self.seconds += time.perf_counter() - t0
        self.states += 1
        return not any(a.collides for a in answers)

    def segment_poses(self, s1, s2, resolution):
        n = max(1, int(math.ceil(self.space.distance(s1, s2) / resolution)))
        tmp = self.space.allocState()
        poses = []
        for k in range(1, n + 1):
            self.space.interpolate(s1, s2, k / n, tmp)
            poses.append(self.pose(tmp))
        return poses

    def motion_valid(self, s1, s2, resolution) -> bool:
        """Motion validity: the states along the segment as candidate states of one request."""
        t0 = time.perf_counter()
        poses = self.segment_poses(s1, s2, resolution)
        out = self.stream.check_states(states=[{self.robot: p} for p in poses], queries=self.collide)
        self.motion_seconds += time.perf_counter() - t0
        self.motion_states += len(poses)
        self.motion_segments += 1
        return not any(s.any_collision for s in out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--addr", default="127.0.0.1:50051", help="server host:port (default: the demo server)")
    ap.add_argument("--png", default="out/plan_ompl.png", help="where to write the figure (empty: draw none)")
    ap.add_argument("--max-degree", type=int, choices=(2, 4, 6, 8), default=8,
                    help="obstacles of a higher degree are replaced by their shape's fit of this degree (default 8: none)")
    ap.add_argument("--margin", type=float, default=0.02, help="collision margin, meters (default 0.02)")
    ap.add_argument("--resolution", type=float, default=0.05, help="motion-check step in OMPL's SE(3) distance (m + rad)")
    ap.add_argument("--time", type=float, default=60.0, help="planning time limit, seconds")
    ap.add_argument("--seed", type=int, default=1, help="OMPL's random seed")
    ap.add_argument("--keep", action="store_true", help="keep the scene on the server")
    ap.add_argument("--delete-bodies", action="store_true", help="delete the bodies this run uploaded at the end")
    args = ap.parse_args(argv)

    from ompl import util as ou

    ou.setLogLevel(ou.LOG_WARN)
    ou.RNG.setSeed(args.seed)

    # An upload certifies sos-convexity with an SDP: ~40 s for a degree-8 body on a release build.
    client = Client(args.addr, timeout=600.0)
    client.wait_ready(10.0)

    scene = client.create_scene(f"plan_ompl {time.strftime('%Y-%m-%d %H:%M:%S')}")
    bodies = []
    try:
        return run(args, client, scene, bodies)
    finally:
        try:
            if not args.keep:
                client.delete_scene(scene)
                if args.delete_bodies:
                    for b in bodies:
                        client.delete_body(b)
        except Exception as e:  # noqa: BLE001 (cleanup must not hide the run's error)
            print(f"cleanup failed: {e}", file=sys.stderr)
        client.close()


_BODY_KEYS = ("degree", "exponents", "coefficients", "center", "scale")


def load_body(client, name, body, stored, uploaded):
    """The id of a stored body named ``name`` with exactly this polynomial, else of a new upload
    (appended to ``uploaded``, and to ``stored`` for the obstacles after it). Returns (id, reused)."""
    want = {k: body[k] for k in _BODY_KEYS}
    for body_id in stored.get(name, []):
        have = json.loads(client.get_body_json(body_id))
        if {k: have.get(k) for k in _BODY_KEYS} == want:
            return body_id, True
    body_id = client.upload_body(name, body)
    uploaded.append(body_id)
    stored.setdefault(name, []).append(body_id)
    return body_id, False


def run(args, client, scene, bodies) -> int:
    """Loads the robot and obstacles into ``scene``, plans, reports and draws."""
    from ompl import base as ob
    from ompl import geometric as og

    # --- the scene ---------------------------------------------------------------------------
    robot_file = REPO / "data" / "demo" / "chair_101.json"
    robot_json = json.loads(robot_file.read_text())
    files = obstacle_files(args.max_degree)
    t0 = time.perf_counter()
    stored = {}
    for b in client.list_bodies():
        stored.setdefault(b.name, []).append(b.body_id)
    robot_body, _ = load_body(client, "plan_ompl/robot chair_101", robot_json, stored, bodies)
    robot = client.add_instance(scene, robot_body, Pose(quat=UPRIGHT, t=START))
    obstacles, drawn = [], []
    for (name, path), pose in zip(files, wall_layout(len(files))):
        body = json.loads(path.read_text())
        t1 = time.perf_counter()
        body_id, reused = load_body(client, "plan_ompl/" + name, body, stored, bodies)
        how = "reused" if reused else f"uploaded in {time.perf_counter() - t1:.2f} s"
        print(f"  obstacle {name:<30} degree {body['degree']} at ({pose.t[0]:+.2f}, {pose.t[1]:+.2f}) m: {body_id} ({how})", flush=True)
        obstacles.append(client.add_instance(scene, body_id, pose))
        drawn.append((name, body["degree"], pose.apply(boundary_points(body))))
    print(f"scene {scene} on {args.addr}: robot chair_101 and {len(obstacles)} obstacles, loaded in {time.perf_counter() - t0:.2f} s")

    # --- OMPL --------------------------------------------------------------------------------
    space = ob.SE3StateSpace()
    bounds = ob.RealVectorBounds(3)
    for i in range(3):
        bounds.setLow(i, BOUNDS_LOW[i])
        bounds.setHigh(i, BOUNDS_HIGH[i])
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)
    si = ss.getSpaceInformation()

    exit_code = 0
    with client.stream(scene) as stream:
        checker = ServiceChecker(stream, robot, obstacles, args.margin, space)
        ss.setStateValidityChecker(checker.is_valid)

        class StreamMotionValidator(ob.MotionValidator):
            def checkMotion(self, s1, s2):  # noqa: N802 (OMPL's name)
                return checker.motion_valid(s1, s2, args.resolution)

        motion_validator = StreamMotionValidator(si)
        si.setMotionValidator(motion_validator)

        def se3(p):
            s = space.allocState()
            s.setXYZ(*p)
            r = s.rotation()
            r.w, r.x, r.y, r.z = UPRIGHT
            return s

        start, goal = se3(START), se3(GOAL)
        ss.setStartAndGoalStates(start, goal)
        ss.setPlanner(og.RRTConnect(si))
        ss.setup()
        t0 = time.perf_counter()
        status = ss.solve(args.time)
        plan_seconds = time.perf_counter() - t0
        if not ss.haveExactSolutionPath():
            print(f"no path found in {plan_seconds:.1f} s ({status})")
            exit_code = 1
        else:
            raw = ss.getSolutionPath()
            raw_states, raw_length = raw.getStateCount(), raw.length()
            t1 = time.perf_counter()
            ss.simplifySolution(min(5.0, args.time))
            simplify_seconds = time.perf_counter() - t1
            path = ss.getSolutionPath()
            waypoints = [checker.pose(path.getState(i)) for i in range(path.getStateCount())]
            # Clearance from the service's distances along the interpolated path (one request).
            dense = [waypoints[0]]
            for i in range(path.getStateCount() - 1):
                dense += checker.segment_poses(path.getState(i), path.getState(i + 1), args.resolution)
            distance_queries = [Query.distance(robot, o) for o in obstacles]
            per_state = stream.check_states(states=[{robot: p} for p in dense], queries=distance_queries)
            clearance = np.array([min(a.distance for a in s.answers) for s in per_state])
            nearest = [int(np.argmin([a.distance for a in s.answers])) for s in per_state]
            k_min = int(np.argmin(clearance))

            n_checked = checker.states + checker.motion_states
            t_checked = checker.seconds + checker.motion_seconds
            xyz = np.array([w.t for w in waypoints])
            translation_length = float(np.sum(np.linalg.norm(np.diff(xyz, axis=0), axis=1)))
            print(f"RRTConnect in SE(3), margin {args.margin} m: exact solution in {plan_seconds:.2f} s, simplified in {simplify_seconds:.2f} s")
            print(
                f"state validity:  {checker.states} states, {checker.states / max(checker.seconds, 1e-9):.0f} states/s "
                f"(one stream request per state, {len(obstacles)} COLLIDE queries each)"
            )
            print(
                f"motion validity: {checker.motion_segments} segments, {checker.motion_states} states, "
                f"{checker.motion_states / max(checker.motion_seconds, 1e-9):.0f} states/s (one request per segment)"
            )
            print(f"all checks:      {n_checked} states in {t_checked:.2f} s = {n_checked / max(t_checked, 1e-9):.0f} states checked per second")
            print(
                f"path: {path.getStateCount()} waypoints (raw {raw_states}), length {path.length():.3f} "
                f"(OMPL SE(3) metric, raw {raw_length:.3f}), translation {translation_length:.3f} m"
            )
            print(
                f"clearance along the path ({len(dense)} states): min {clearance[k_min]:.3f} m "
                f"(to {files[nearest[k_min]][0]}), mean {clearance.mean():.3f} m"
            )
            for i, w in enumerate(waypoints):
                print(f"  waypoint {i}: t = ({w.t[0]:+.3f}, {w.t[1]:+.3f}, {w.t[2]:+.3f}) m, q = ({', '.join(f'{v:+.3f}' for v in w.quat)})")
            if args.png:
                draw(args.png, drawn, robot_json, waypoints, dense, clearance)
                print(f"wrote {args.png}")

    return exit_code


def draw(png, obstacles, robot_json, waypoints, dense, clearance):
    """Top (x, y) and side (x, z) views: obstacles as filled silhouettes (projected convex hulls
    of their boundaries), the chair's silhouette along the path, the path colored by clearance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    robot_pts = boundary_points(robot_json, n_dirs=600)
    # The chair at every waypoint and about every 0.35 m along the interpolated path.
    shown, last = [], None
    for p in dense:
        if last is None or np.linalg.norm(np.subtract(p.t, last.t)) >= 0.35:
            shown.append(p)
            last = p
    shown.append(dense[-1])
    path = np.array([p.t for p in dense])
    xyz = np.array([w.t for w in waypoints])
    fig, axes = plt.subplots(1, 2, figsize=(15, 6.2), gridspec_kw={"width_ratios": [1.0, 1.0]}, layout="constrained")
    for ax, (i, j, title) in zip(axes, [(0, 1, "top view (x, y)"), (0, 2, "side view (x, z)")]):
        for name, degree, pts in obstacles:
            h = hull2d(pts[:, [i, j]])
            ax.fill(h[:, 0], h[:, 1], color="0.65", alpha=0.55, ec="0.25", lw=0.8, zorder=1)
            if i == 0 and j == 1:
                c = pts.mean(axis=0)
                short = name.split("/")[-1].replace("_101", "").replace("_10", "")
                ax.text(c[i], c[j], f"{short}\n2d={degree}", ha="center", va="center", fontsize=6.5, zorder=2)
        for k, p in enumerate(shown):
            h = hull2d(p.apply(robot_pts)[:, [i, j]])
            ax.plot(h[:, 0], h[:, 1], color=plt.cm.viridis(k / max(1, len(shown) - 1)), lw=0.9, alpha=0.8, zorder=3)
        sc = ax.scatter(path[:, i], path[:, j], c=clearance, cmap="plasma", s=7, zorder=4)
        ax.plot(xyz[:, i], xyz[:, j], "k-", lw=0.8, zorder=5)
        ax.plot(xyz[:, i], xyz[:, j], "ko", ms=4, zorder=6, label="waypoints")
        ax.plot([START[i]], [START[j]], "g*", ms=15, zorder=7, label="start")
        ax.plot([GOAL[i]], [GOAL[j]], "r*", ms=15, zorder=7, label="goal")
        ax.set_xlabel("xyz"[i] + " [m]")
        ax.set_ylabel("xyz"[j] + " [m]")
        ax.set_title(title)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower left", fontsize=8)
    fig.colorbar(sc, ax=axes, shrink=0.6, label="clearance (min distance to the obstacles, from the service) [m]")
    fig.suptitle("chair_101 planned by OMPL RRTConnect in SE(3) through fitted PSB bodies; Sublevel COLLIDE / DISTANCE over one QueryStream")
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # OMPL's nanobind module reports leaked bindings at interpreter exit; skip that noise.
    os._exit(code)
