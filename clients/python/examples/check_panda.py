#!/usr/bin/env python3
"""Check Panda configurations in a MotionBenchMaker bookshelf, from Python.

Against the demo server (``bash scripts/demo`` or ``cargo run --release -- serve --demo``, default
address 127.0.0.1:50051), which holds the fitted Panda as the robot ``panda`` and MotionBenchMaker's
``bookshelf_small/scene0001.yaml`` as the scene ``mbm_bookshelf``:

    python clients/python/examples/check_panda.py [--addr HOST:PORT]

Finds both by name, checks two joint configurations of the scene's labelled set
(``data/robots/mbm_panda/labels_obj.csv``, bookshelf_small scene 1, rows idx 1 and 6: free and
colliding on the collision meshes) in one call, and prints each verdict with the closest (or
colliding) link and shelf object, beside the meshes' label. Exits 1 when a verdict differs from its
label.
"""

from __future__ import annotations

import argparse
import sys

from sublevel_client import DEFAULT_ADDR, Client

# panda_joint1..7 (radians) and the collision meshes' verdict, from labels_obj.csv.
CONFIGURATIONS = [
    ([0.625670703, -0.0449929212, -2.14350657, -0.296874864, 0.754076933, 1.11437334, 0.0438582887], False),
    ([1.64366033, -1.22615717, -2.06301051, -0.37241723, 0.58747913, 1.09051868, -0.24421097], True),
]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--addr", default=DEFAULT_ADDR, help=f"server host:port (default {DEFAULT_ADDR})")
    args = ap.parse_args(argv)

    with Client(args.addr) as c:
        panda = next(r for r in c.list_robots() if r.name == "panda")
        shelf = c.find_scene("mbm_bookshelf")
        q = [q for q, _ in CONFIGURATIONS]
        r = c.check_configurations(panda.robot_id, q, scene=shelf, distance=True)  # columns: panda.joint_names
        print(f"robot panda {panda.robot_id} ({panda.dof} joints), scene mbm_bookshelf {shelf}")
        agree = True
        for k, (_, label) in enumerate(CONFIGURATIONS):
            verdict = "collides" if r.collides[k] else "free"
            print(
                f"q{k}: {verdict:<8} distance {r.distance[k]:.4f} m, {r.robot_link[k]} - {r.world_object[k]}"
                f"   (mesh label: {'collides' if label else 'free'})"
            )
            agree &= bool(r.collides[k]) == label
    print("verdicts equal the mesh labels" if agree else "a verdict differs from its mesh label")
    return 0 if agree else 1


if __name__ == "__main__":
    sys.exit(main())
