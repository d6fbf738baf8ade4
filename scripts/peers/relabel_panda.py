#!/usr/bin/env python3
"""Relabel the MotionBenchMaker Panda configurations with the collision meshes read as written.

The robots peer (its `coal_peer.py`) labels configurations with pinocchio + coal, whose mesh
loader (assimp) reads `link6.obj` — one object with 17 `usemtl` groups — into a different surface:
1 126 of its 1 308 triangles join other vertices than the file's faces name (edges shared by up to
27 triangles; some vertices 4.3 mm away from any of the file's). Every other Panda link loads as
written. This script keeps the peer's code (scenes, pairs, allowed collisions, pruned minimum
distance) and replaces each robot mesh by a coal BVH of the OBJ's own vertices and faces (polygons
split into fans), then labels the same configurations again.

    mkdir -p /tmp/mbm && tar xjf data/robots/mbm_panda/problems.tar.bz2 -C /tmp/mbm
    python scripts/peers/relabel_panda.py --peer-dir PEER_DIR \
        --problems-dir /tmp/mbm/problems --out data/robots/mbm_panda/labels_obj.csv

PEER_DIR is a checkout of the robots peer (its `coal_peer.py`, `panda/` and `labels/`); it is not
part of this repository. Needs `pin==4.1.0` (bundles coal 3.0.3), numpy and pyyaml. Prints the rows
whose labels change.
"""
import argparse
import csv
import sys
from pathlib import Path

import numpy as np


def read_obj(path):
    verts, tris = [], []
    for line in Path(path).read_text().splitlines():
        tok = line.split("#")[0].split()
        if not tok:
            continue
        if tok[0] == "v":
            verts.append([float(x) for x in tok[1:4]])
        elif tok[0] == "f":
            idx = [int(t.split("/")[0]) for t in tok[1:]]
            idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
            for j in range(1, len(idx) - 1):
                tris.append([idx[0], idx[j], idx[j + 1]])
    return np.array(verts), np.array(tris)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--peer-dir", required = True, help = "the robots peer's checkout (coal_peer.py, panda/, labels/)")
    ap.add_argument("--problems-dir", required = True, help = "dir with <scenario>_panda/sceneNNNN.yaml")
    ap.add_argument("--labels", default = None, help = "the peer's labels (default PEER/labels/mbm_panda_labels.csv)")
    ap.add_argument("--out", required = True)
    args = ap.parse_args()
    peer = Path(args.peer_dir)
    sys.path.insert(0, str(peer))
    import coal
    import pinocchio as pin
    import coal_peer

    build = pin.buildGeomFromUrdf

    def literal_meshes(*a, **k):
        geom = build(*a, **k)
        for g in geom.geometryObjects:
            if g.meshPath and g.meshPath.endswith(".obj"):
                v, t = read_obj(g.meshPath)
                m = coal.BVHModelOBBRSS()
                m.beginModel(len(t), len(v))
                m.addVertices(v)
                m.addTriangles(t)
                m.endModel()
                g.geometry = m
        return geom

    pin.buildGeomFromUrdf = literal_meshes
    panda = peer / "panda"
    urdf = panda / "panda.urdf"
    model = pin.buildModelFromUrdf(str(urdf))
    labels = Path(args.labels) if args.labels else peer / "labels" / "mbm_panda_labels.csv"
    rows = list(csv.DictReader(open(labels)))
    fields = list(rows[0].keys())
    out_rows, changed = [], 0
    checker, current = None, None
    for r in rows:
        key = (r["scenario"], int(r["scene"]))
        if key != current:
            objects, acm = coal_peer.load_scene(Path(args.problems_dir) / f"{key[0]}_panda" / f"scene{key[1]:04d}.yaml")
            checker = coal_peer.SceneChecker(model, urdf, panda, objects, acm)
            current = key
        q = np.array([float(r[f"q{i}"]) for i in range(1, 8)])
        anyc, world, selfc, pairs = checker.label(q)
        d = checker.min_world_distance_pruned(q)
        new = dict(r)
        new.update(collides = int(anyc), collides_world = int(world), collides_self = int(selfc),
                   min_world_dist_m = f"{d:.6f}", colliding_pairs = pairs)
        if any(str(new[c]) != str(r[c]) for c in ("collides", "collides_world", "collides_self")):
            changed += 1
            print(f"{r['scenario']} {r['scene']} {r['idx']}: collides {r['collides']}->{new['collides']} "
                  f"world {r['collides_world']}->{new['collides_world']} self {r['collides_self']}->{new['collides_self']} "
                  f"pairs {r['colliding_pairs']!r}->{pairs!r}")
        out_rows.append(new)
    Path(args.out).parent.mkdir(parents = True, exist_ok = True)
    with open(args.out, "w", newline = "") as f:
        w = csv.DictWriter(f, fieldnames = fields)
        w.writeheader()
        w.writerows(out_rows)
    print(f"{len(rows)} configurations, {changed} verdicts changed -> {args.out}")


if __name__ == "__main__":
    main()
