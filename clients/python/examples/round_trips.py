"""Round trips of a Python planner against the service, as a user measures them.

Against the demo server (``cargo run --release -- serve --demo``, default address 127.0.0.1:50051),
on its ``demo`` scene (the chair and the human): times each call ``--repeats`` times with the typed
client and prints the median, p99 and calls per second of each.

    python clients/python/examples/round_trips.py [--addr HOST:PORT] [--repeats 300]

Calls timed: Distance (unary); BatchQuery of 1, 5, 19, 100, 400 and 1000 pairs (one message per
pair); a planner's state check the old way (SetPoses of one instance, then a 19-pair BatchQuery:
a store write per state); the same state check on a QueryStream (the pose and 19 queries in one
message, nothing written); the same in columns; a 1000-pair BatchQuery in columns (numpy arrays
back), warm (the pair's warm start, the same poses: no Newton step) and cold (every pair solved from
scratch, four pairs per SIMD pass); a sampling planner's check of 256 candidate states (the chair at random poses around the
human, as in ``sublevel bench``'s cold queries) in one Query, with the distance query cold (the
server then solves four states per SIMD pass) and not cold (each state warm-started from the one
before where that is near; random states are farther apart than the warm starts' reach, so the server
solves them like cold ones and keeps their warm starts); the same 256 states as one array of poses, answers in one set of columns
(``Client.query_state_columns``), cold and warm, and a collide query (margin 0, cold) over them.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from sublevel_client import DEFAULT_ADDR, Client, Pose, Query


def timed(fn, repeats: int):
    fn()  # warm-up (connection, warm starts)
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    samples.sort()
    p50 = statistics.median(samples)
    p99 = samples[min(len(samples) - 1, int(0.99 * len(samples)))]
    return p50, p99


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--addr", default=DEFAULT_ADDR)
    ap.add_argument("--repeats", type=int, default=300)
    args = ap.parse_args()

    c = Client(args.addr)
    c.wait_ready()
    scene = c.find_scene("demo")
    a, b = [i.instance_id for i in c.get_scene(scene).instances]
    stored = {i.instance_id: i.pose for i in c.get_scene(scene).instances}
    rows = []

    def row(name, fn, pairs):
        p50, p99 = timed(fn, args.repeats)
        rows.append((name, p50, p99, pairs))

    row("Distance, unary", lambda: c.distance(scene, a, b), 1)
    for k in (1, 5, 19, 100, 400, 1000):
        queries = [Query.distance(a, b)] * k
        row(f"BatchQuery, {k} pairs", lambda q=queries: c.batch(scene, q), k)
    pose = stored[b]
    nudged = Pose(quat=pose.quat, t=np.asarray(pose.t) + [0.0, 0.001, 0.0])
    q19 = [Query.distance(a, b)] * 19

    def set_poses_then_batch():
        c.set_poses(scene, {b: nudged})
        c.batch(scene, q19)

    row("SetPoses (1 instance) + BatchQuery (19 pairs)", set_poses_then_batch, 19)
    with c.stream(scene) as s:
        row("QueryStream step: 1 pose + 19 queries", lambda: s.check(poses={b: nudged}, queries=q19), 19)
        first, second = [a] * 19, [b] * 19
        row(
            "QueryStream step in columns: 1 pose + 19 pairs",
            lambda: s.check_columns("distance", first, second, poses={b: nudged}),
            19,
        )
    first, second = [a] * 1000, [b] * 1000
    row("BatchQuery in columns, 1000 pairs", lambda: c.batch_columns(scene, "distance", first, second), 1000)
    row(
        "BatchQuery in columns, 1000 pairs, cold",
        lambda: c.batch_columns(scene, "distance", first, second, cold=True),
        1000,
    )
    # A sampling planner's candidate states: the chair (instance a) at random poses in a 5 m cube
    # around its stored place, uniform rotations (seed 7).
    rng = np.random.default_rng(7)
    states = []
    for _ in range(256):
        q = rng.uniform(-1.0, 1.0, 4)
        t = np.asarray(stored[a].t) + rng.uniform(-2.5, 2.5, 3)
        states.append({a: Pose(quat=tuple(q / np.linalg.norm(q)), t=t)})
    for cold in (True, False):
        queries = [Query.distance(a, b, cold=cold)]
        name = f"Query, 256 states x 1 distance, {'cold' if cold else 'warm from the last state'}"
        row(name, lambda q=queries: c.query(scene, queries=q, states=states), 256)
    # The same states as one array both ways (QueryRequest.state_columns: no message per state).
    packed = np.array([[[*s[a].quat, *s[a].t]] for s in states])
    for cold in (True, False):
        name = f"Query, 256 states as one array, {'cold' if cold else 'warm'}"
        row(name, lambda cold=cold: c.query_state_columns(scene, "distance", [a], [b], [a], packed, cold=cold), 256)
    # The same states asking COLLIDE (margin 0, cold): the cheap bounds (bounding spheres, then the
    # separating axis) clear most states without a solve.
    row(
        "Query, 256 states as one array, collide, cold",
        lambda: c.query_state_columns(scene, "collide", [a], [b], [a], packed, margin=0.0, cold=True),
        256,
    )
    c.set_poses(scene, {b: pose})  # leave the demo scene as it was

    print(f"{args.repeats} calls each against {args.addr} (Python client, one connection)")
    print(f"{'call':<50} {'p50 ms':>8} {'p99 ms':>8} {'calls/s':>9} {'pairs/s':>10}")
    for name, p50, p99, pairs in rows:
        print(f"{name:<50} {p50 * 1e3:>8.3f} {p99 * 1e3:>8.3f} {1 / p50:>9.0f} {pairs / p50:>10.0f}")


if __name__ == "__main__":
    main()
