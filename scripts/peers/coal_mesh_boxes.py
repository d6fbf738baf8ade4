#!/usr/bin/env python3
"""Reference distances between a triangle mesh and boxes from coal 3.0.3 (exact mesh BVH against a box).

For the compound-body test: a compound body fitted to the mesh (`sublevel fit MESH --parts`) against the same
boxes must never be farther than the mesh (its leaves contain the mesh) and no nearer than the mesh less the
compound's largest leaf excess.

    python scripts/peers/coal_mesh_boxes.py data/psb/chair_101.off --cases 200 --seed 3 \
        --output crates/lab/tests/data/coal_chair_boxes.csv

Needs numpy and coal==3.0.3 (scripts/peers/coal_primitives.sh makes such a venv under ${COAL_WORK:-/tmp/coal-peer}).
Deterministic for a given seed (numpy's PCG64).

Boxes: full side lengths uniform in [0.05, 0.5] m each, a uniformly random rotation, the center at the mesh's
bounding-box center plus a random direction times a distance uniform in [0.2, 1.2] x the mesh's bounding
radius, so that most boxes are near the mesh and a quarter or so overlap it. The mesh stays at the identity.

Columns (one header row; numbers are Python repr):
    sx, sy, sz                  the box's full side lengths (meters)
    q_w, q_x, q_y, q_z          its rotation (unit quaternion, w >= 0)
    t_x, t_y, t_z               its center (world = mesh frame)
    distance                    coal.distance between the mesh (BVHModel OBBRSS) and the box: the separation when
                                apart; 0 or below when they intersect (mesh-box penetration is not a volume's)
    overlapping                 1 when coal.collide reports a contact, else 0
"""
import argparse
import sys

import numpy as np
import coal


def read_off(path):
    tokens = open(path).read().split()
    if tokens[0] != "OFF":
        raise SystemExit(f"{path}: not an OFF file")
    nv, nf = int(tokens[1]), int(tokens[2])
    v = np.array(tokens[4:4 + 3 * nv], dtype=float).reshape(nv, 3)
    f, i = [], 4 + 3 * nv
    for _ in range(nf):
        k = int(tokens[i])
        idx = [int(t) for t in tokens[i + 1:i + 1 + k]]
        for j in range(1, k - 1):
            f.append((idx[0], idx[j], idx[j + 1]))
        i += 1 + k
    return v, np.array(f, dtype=int)


def random_rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mesh")
    ap.add_argument("--cases", type=int, default=200)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--output", required=True)
    args = ap.parse_args()
    v, f = read_off(args.mesh)
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(f), len(v))
    model.addVertices(v)
    model.addTriangles(f)
    model.endModel()
    lo, hi = v.min(axis=0), v.max(axis=0)
    center, radius = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo)
    rng = np.random.default_rng(args.seed)
    dreq, creq = coal.DistanceRequest(), coal.CollisionRequest()
    rows, overlapping = [], 0
    for _ in range(args.cases):
        size = rng.uniform(0.05, 0.5, size=3)
        q = random_rotation(rng)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        t = center + d * rng.uniform(0.2, 1.2) * radius
        box = coal.Box(*size)
        tf = coal.Transform3s(coal.Quaternion(q[0], q[1], q[2], q[3]).matrix(), t)
        dres, cres = coal.DistanceResult(), coal.CollisionResult()
        dist = coal.distance(model, coal.Transform3s(), box, tf, dreq, dres)
        hit = coal.collide(model, coal.Transform3s(), box, tf, creq, cres) > 0
        overlapping += hit
        rows.append(",".join(repr(float(x)) for x in [*size, *q, *t, dist]) + f",{int(hit)}")
    with open(args.output, "w") as out:
        out.write("sx,sy,sz,q_w,q_x,q_y,q_z,t_x,t_y,t_z,distance,overlapping\n")
        out.write("\n".join(rows) + "\n")
    print(f"{args.mesh}: {len(v)} vertices, {len(f)} triangles; {args.cases} boxes, {overlapping} overlapping",
          file=sys.stderr)


if __name__ == "__main__":
    main()
