#!/usr/bin/env python3
"""Check that Sublevel's self-collision verdicts agree with pinocchio + coal on example-robot-data robots.

For each robot named with ``--robot`` (URDF and SRDF from the PyPI package ``example-robot-data``):

1. fits it with ``sublevel robot fit`` into a fresh (cold) cache and times it; keeps its stderr
   (``warning: ...`` lines for skipped SRDF entries, ``not checked: A – B`` lines for rigid pairs,
   the summary line with the links with geometry and the self pairs checked);
2. draws N configurations uniformly within the URDF limits of the configuration's joints (every
   revolute / continuous / prismatic joint that is not a mimic joint, in URDF order; continuous
   joints in [-pi, pi]) with ``numpy.random.default_rng(seed)`` and writes them as a CSV;
3. checks them with ``sublevel robot check ROBOT.json --configs CSV --json --no-distance`` (self
   collision only: no scene);
4. checks them with pinocchio + coal on the URDF's collision meshes: fixed base, ``mimic=False``
   (mimic joints are separate joints, set to ``multiplier * q[source] + offset``),
   ``addAllCollisionPairs`` then ``removeCollisionPairs`` with the SRDF, ``computeCollisions``;
5. compares the verdicts (both collide, both free, misses = pinocchio collides and Sublevel says
   free, false collisions = Sublevel collides and pinocchio says free) and analyses every
   disagreement with pinocchio's distances (``computeDistances``): the colliding pair(s), the nearest
   pair, the distance of the pair Sublevel named, whether it is a contact within ``--tie`` meters
   (numerical tie) or a real disagreement, or whether it comes from a pair only one side checks;
6. compares the two self-pair sets (as link pairs) and prints one row per robot.

    python robot_agreement.py --sublevel target/release/sublevel \\
        --robots-dir SITE_PACKAGES/cmeel.prefix/share/example-robot-data/robots \\
        --robot xarm7 --robot pr2 --robot talos --configs 2000 --seed 1 --out DIR [--json results.json]

Mesh URIs are ``package://example-robot-data/robots/...``, so the package directory given to both
sides is the robots directory's grandparent (``.../share``) unless ``--package-dir`` says otherwise.
Needs numpy, pin (pinocchio + coal) and example-robot-data. Exits 1
when a robot has a miss, or when a fit or a check failed.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Dict, FrozenSet, List, Tuple

import numpy as np

# name -> (URDF, SRDF), relative to the robots directory of example-robot-data.
ROBOTS: Dict[str, Tuple[str, str]] = {
    "xarm7": ("xarm_description/urdf/xarm7.urdf", "xarm_description/srdf/xarm7.srdf"),
    "pr2": ("pr2_description/urdf/pr2.urdf", "pr2_description/srdf/pr2.srdf"),
    "talos": ("talos_data/robots/talos_reduced.urdf", "talos_data/srdf/talos.srdf"),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "ur_description/srdf/ur5.srdf"),
    "panda": ("panda_description/urdf/panda.urdf", "panda_description/srdf/panda.srdf"),
    "baxter": ("baxter_description/urdf/baxter.urdf", "baxter_description/srdf/baxter_manipulation.srdf"),
    "z1": ("z1_description/urdf/z1.urdf", "z1_description/srdf/z1.srdf"),
    "kinova": ("kinova_description/robots/kinova.urdf", "kinova_description/srdf/kinova.srdf"),
}

MOVING = ("revolute", "continuous", "prismatic")
Pair = FrozenSet[str]


def pair_str(p) -> str:
    a, b = sorted(p)
    return f"{a} – {b}"


# -- URDF -------------------------------------------------------------------------------------------
class Urdf:
    """The joints and links of a URDF that both sides' configuration handling needs."""

    def __init__(self, path: Path):
        root = ET.parse(path).getroot()
        self.links_with_geometry = [l.get("name") for l in root.findall("link") if l.find("collision") is not None]
        self.joints = []  # (name, type, parent, child)
        self.limits: Dict[str, Tuple[float, float]] = {}
        self.mimic: Dict[str, Tuple[str, float, float]] = {}  # joint -> (source, multiplier, offset)
        for j in root.findall("joint"):
            name, kind = j.get("name"), j.get("type")
            self.joints.append((name, kind, j.find("parent").get("link"), j.find("child").get("link")))
            m = j.find("mimic")
            if m is not None and kind in MOVING:
                self.mimic[name] = (m.get("joint"), float(m.get("multiplier", 1.0)), float(m.get("offset", 0.0)))
            if kind == "continuous":
                self.limits[name] = (-math.pi, math.pi)
            elif kind in MOVING:
                lim = j.find("limit")
                lo = float(lim.get("lower", 0.0)) if lim is not None else 0.0
                hi = float(lim.get("upper", 0.0)) if lim is not None else 0.0
                self.limits[name] = (lo, hi)
        # The configuration: the moving joints that are not mimic joints, in URDF order.
        self.config_joints = [n for n, k, _, _ in self.joints if k in MOVING and n not in self.mimic]

    def rigid_groups(self) -> Dict[str, str]:
        """link -> representative of the rigid body it belongs to (links joined by fixed joints)."""
        parent: Dict[str, str] = {}

        def find(x: str) -> str:
            parent.setdefault(x, x)
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        for _, kind, p, c in self.joints:
            find(p), find(c)
            if kind == "fixed":
                parent[find(p)] = find(c)
        return {l: find(l) for l in list(parent)}

    def joint_values(self, q: np.ndarray) -> Dict[str, float]:
        """Every moving joint's value for the configuration q (config_joints order), mimics included."""
        vals = dict(zip(self.config_joints, map(float, q)))

        def value(name: str, depth: int = 0) -> float:
            if name in vals:
                return vals[name]
            if name in self.mimic and depth < 32:
                src, mul, off = self.mimic[name]
                v = mul * value(src, depth + 1) + off
                vals[name] = v
                return v
            return 0.0

        for n in self.mimic:
            value(n)
        return vals


# -- Sublevel ---------------------------------------------------------------------------------------
def run_fit(args, urdf: Path, srdf: Path, work: Path) -> dict:
    cache = work / "cache"
    if cache.exists():
        shutil.rmtree(cache)
    out = work / "robot.json"
    cmd = [args.sublevel, "robot", "fit", str(urdf), "--srdf", str(srdf), "--package-dir", str(args.package_dir),
           "--output", str(out), "--cache", str(cache)]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=args.fit_timeout)
        rc, err = p.returncode, p.stderr
    except subprocess.TimeoutExpired as e:
        rc, err = None, (e.stderr.decode() if isinstance(e.stderr, bytes) else (e.stderr or ""))
    seconds = time.perf_counter() - t0
    (work / "fit.stderr").write_text(err)
    res = {"command": cmd, "seconds": seconds, "rc": rc, "ok": rc == 0 and out.exists(),
           "warnings": [l.strip() for l in err.splitlines() if l.strip().startswith("warning")],
           "not_checked": [l.strip() for l in err.splitlines() if l.strip().startswith("not checked")]}
    if rc is None:
        res["error"] = f"timed out after {args.fit_timeout} s; last stderr: " + " | ".join(err.splitlines()[-3:])
    elif rc != 0:
        res["error"] = err.strip()[-2000:]
    m = re.search(r"(\d+) links with geometry.*?(\d+) self pairs checked", err)
    if m:
        res["links_with_geometry"], res["self_pairs_checked"] = int(m.group(1)), int(m.group(2))
    return res


def sublevel_pairs(robot_json: Path, urdf: Urdf) -> Tuple[set, List[str]]:
    """The link pairs Sublevel checks, by its stated model: links with geometry, minus the robot
    file's allowed pairs (the SRDF's known ones), minus pairs inside one rigid body."""
    d = json.loads(robot_json.read_text())
    links = sorted({g["link"] for g in d["geometries"]})
    allowed = {frozenset(p) for p in d.get("allowed_pairs", [])}
    group = urdf.rigid_groups()
    pairs = set()
    for i, a in enumerate(links):
        for b in links[i + 1:]:
            p = frozenset((a, b))
            if p not in allowed and group.get(a, a) != group.get(b, b):
                pairs.add(p)
    return pairs, links


def run_check(args, robot_json: Path, csv: Path, n: int, work: Path) -> dict:
    cmd = [args.sublevel, "robot", "check", str(robot_json), "--configs", str(csv), "--json", "--no-distance"]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    (work / "check.jsonl").write_text(p.stdout)
    (work / "check.stderr").write_text(p.stderr)
    res = {"command": cmd, "rc": p.returncode, "wall_seconds": wall}
    if p.returncode != 0:
        res["error"] = p.stderr.strip()[-2000:]
        return res
    rows = [json.loads(l) for l in p.stdout.splitlines() if l.strip()]
    rows.sort(key=lambda r: r["config"])
    if len(rows) != n or [r["config"] for r in rows] != list(range(n)):
        res["error"] = f"expected {n} configurations, got {len(rows)} JSON lines"
        return res
    res["collides"] = [bool(r["self"]) for r in rows]
    res["world"] = sum(bool(r["world"]) for r in rows)
    res["self_pair"] = [r.get("self_pair") for r in rows]
    res["not_converged"] = sum(not r.get("converged", True) for r in rows)
    m = re.search(r"([\d.]+)\s*(µs|us|ms|ns|s) per configuration", p.stderr)
    if m:
        scale = {"ns": 1e-3, "µs": 1.0, "us": 1.0, "ms": 1e3, "s": 1e6}[m.group(2)]
        res["us_per_config"] = float(m.group(1)) * scale
    return res


# -- pinocchio + coal -------------------------------------------------------------------------------
class Reference:
    def __init__(self, urdf_path: Path, srdf_path: Path, package_dir: Path, urdf: Urdf):
        import pinocchio as pin

        self.pin = pin
        self.urdf = urdf
        self.model, self.cmodel = pin.buildModelsFromUrdf(
            str(urdf_path), package_dirs=[str(package_dir)], geometry_types=pin.GeometryType.COLLISION, mimic=False)
        self.cmodel.addAllCollisionPairs()
        pin.removeCollisionPairs(self.model, self.cmodel, str(srdf_path))
        self.data, self.gdata = self.model.createData(), self.cmodel.createData()
        self.geom_link = [self.model.frames[g.parentFrame].name for g in self.cmodel.geometryObjects]
        self.geom_name = [g.name for g in self.cmodel.geometryObjects]
        self.cp = [(cp.first, cp.second) for cp in self.cmodel.collisionPairs]
        self.cp_link = [frozenset((self.geom_link[a], self.geom_link[b])) for a, b in self.cp]
        self.pairs = set(self.cp_link)
        self.links = sorted(set(self.geom_link))

    def q(self, cfg: np.ndarray) -> np.ndarray:
        vals = self.urdf.joint_values(cfg)
        q = self.pin.neutral(self.model)
        for j in range(1, self.model.njoints):
            name, iq, nq = self.model.names[j], self.model.idx_qs[j], self.model.nqs[j]
            v = vals.get(name, 0.0)
            if nq == 1:
                q[iq] = v
            elif nq == 2:  # continuous: (cos, sin)
                q[iq], q[iq + 1] = math.cos(v), math.sin(v)
            else:
                raise ValueError(f"joint {name} with nq={nq} is not handled")
        return q

    def colliding_pairs(self, q: np.ndarray) -> List[int]:
        self.pin.computeCollisions(self.model, self.data, self.cmodel, self.gdata, q, False)
        return [k for k, r in enumerate(self.gdata.collisionResults) if r.isCollision()]

    def time_verdicts(self, qs: List[np.ndarray]) -> float:
        """Seconds per configuration of a verdict (stop at the first collision), FK included."""
        t0 = time.perf_counter()
        for q in qs:
            self.pin.computeCollisions(self.model, self.data, self.cmodel, self.gdata, q, True)
        return (time.perf_counter() - t0) / max(1, len(qs))

    def distances(self, q: np.ndarray) -> List[float]:
        self.pin.computeDistances(self.model, self.data, self.cmodel, self.gdata, q)
        return [r.min_distance for r in self.gdata.distanceResults]

    def penetrations(self, q: np.ndarray, pairs: List[int]) -> Dict[int, float]:
        """coal's penetration depth (negative: overlap) of each colliding pair: the deepest of its contacts,
        a triangle-pair estimate for meshes (computeDistances gives 0 for overlapping meshes)."""
        reqs = self.gdata.collisionRequests
        for k in pairs:
            reqs[k].enable_contact, reqs[k].num_max_contacts = True, 16
        self.pin.computeCollisions(self.model, self.data, self.cmodel, self.gdata, q, False)
        out = {}
        for k in pairs:
            depths = [c.penetration_depth for c in self.gdata.collisionResults[k].getContacts()]
            out[k] = min(depths) if depths else float("nan")
            reqs[k].enable_contact, reqs[k].num_max_contacts = False, 1
        return out

    def pair_desc(self, k: int) -> str:
        a, b = self.cp[k]
        return f"{self.geom_name[a]} – {self.geom_name[b]} ({pair_str(self.cp_link[k])})"


def analyse(ref: Reference, q: np.ndarray, colliding: List[int], sub_pair, sub_pairs: set, tie: float) -> dict:
    """A disagreement's pinocchio distances and its classification."""
    d = ref.distances(q)
    out = {"pin_colliding": [ref.pair_desc(k) for k in colliding]}
    if colliding:  # miss: pinocchio collides, Sublevel free
        pen = ref.penetrations(q, colliding)
        worst = min(colliding, key=lambda k: pen[k])
        out["pin_colliding_distances"] = {ref.pair_desc(k): d[k] for k in colliding}
        out["pin_colliding_penetration"] = {ref.pair_desc(k): pen[k] for k in colliding}
        out["distance"] = pen[worst]
        only_pin = [pair_str(ref.cp_link[k]) for k in colliding if ref.cp_link[k] not in sub_pairs]
        if len(only_pin) == len(colliding):
            out["class"] = "pair only pinocchio checks: " + ", ".join(sorted(set(only_pin)))
        else:
            out["class"] = "tie" if abs(pen[worst]) <= tie else "real"
    else:  # false collision: Sublevel collides, pinocchio free
        near = int(np.argmin(d))
        out["nearest"] = ref.pair_desc(near)
        out["nearest_distance"] = d[near]
        sp = frozenset(sub_pair) if sub_pair else None
        out["sublevel_pair"] = pair_str(sp) if sp else None
        ks = [k for k, p in enumerate(ref.cp_link) if p == sp]
        if sp is not None and ks:
            out["distance"] = min(d[k] for k in ks)
            out["class"] = "tie" if out["distance"] <= tie else "real"
        elif sp is not None:
            out["distance"] = None
            out["class"] = "pair only Sublevel checks"
        else:
            out["distance"], out["class"] = near, "real"
    return out


# -- one robot --------------------------------------------------------------------------------------
def run_robot(args, name: str) -> dict:
    urdf_rel, srdf_rel = ROBOTS[name]
    urdf_path, srdf_path = args.robots_dir / urdf_rel, args.robots_dir / srdf_rel
    work = args.out / name
    work.mkdir(parents=True, exist_ok=True)
    urdf = Urdf(urdf_path)
    res: dict = {"robot": name, "urdf": str(urdf_path), "srdf": str(srdf_path), "dof": len(urdf.config_joints),
                 "mimic_joints": len(urdf.mimic)}
    log = lambda s: print(f"[{name}] {s}", file=sys.stderr, flush=True)  # noqa: E731

    log(f"fitting ({len(urdf.config_joints)} joints, {len(urdf.links_with_geometry)} links with <collision>)")
    fit = run_fit(args, urdf_path, srdf_path, work)
    res["fit"] = fit
    log(f"fit: rc {fit['rc']}, {fit['seconds']:.1f} s, {len(fit['warnings'])} warnings, "
        f"{len(fit['not_checked'])} 'not checked' lines")
    if not fit["ok"]:
        log("fit failed: " + fit.get("error", "")[-500:])
        return res

    # Configurations.
    rng = np.random.default_rng(args.seed)
    lo = np.array([urdf.limits[j][0] for j in urdf.config_joints])
    hi = np.array([urdf.limits[j][1] for j in urdf.config_joints])
    Q = rng.uniform(lo, hi, size=(args.configs, len(lo)))
    csv = work / "configs.csv"
    with open(csv, "w") as f:
        f.write(",".join(urdf.config_joints) + "\n")
        for row in Q:
            f.write(",".join(repr(float(x)) for x in row) + "\n")

    # Pair sets.
    ref = Reference(urdf_path, srdf_path, args.package_dir, urdf)
    sub_pairs, sub_links = sublevel_pairs(work / "robot.json", urdf)
    res["pairs"] = {
        "sublevel_reported": fit.get("self_pairs_checked"),
        "sublevel_derived": len(sub_pairs),
        "pinocchio_link_pairs": len(ref.pairs),
        "pinocchio_geometry_pairs": len(ref.cp),
        "only_sublevel": sorted(pair_str(p) for p in sub_pairs - ref.pairs),
        "only_pinocchio": sorted(pair_str(p) for p in ref.pairs - sub_pairs),
        "links_sublevel": len(sub_links), "links_pinocchio": len(ref.links),
        "links_only_sublevel": sorted(set(sub_links) - set(ref.links)),
        "links_only_pinocchio": sorted(set(ref.links) - set(sub_links)),
    }
    log(f"pairs: sublevel {fit.get('self_pairs_checked')} (derived {len(sub_pairs)}), pinocchio {len(ref.pairs)} link "
        f"pairs ({len(ref.cp)} geometry pairs); only sublevel {len(sub_pairs - ref.pairs)}, "
        f"only pinocchio {len(ref.pairs - sub_pairs)}")

    log(f"sublevel check of {args.configs} configurations")
    chk = run_check(args, work / "robot.json", csv, args.configs, work)
    res["check"] = {k: v for k, v in chk.items() if k not in ("collides", "self_pair")}
    if "error" in chk:
        log("check failed: " + chk["error"][-500:])
        return res

    log("pinocchio reference")
    qs = [ref.q(c) for c in Q]
    pin_coll = [ref.colliding_pairs(q) for q in qs]
    res["pin_us_per_config"] = ref.time_verdicts(qs) * 1e6

    sub_coll = chk["collides"]
    counts = {"both_collide": 0, "both_free": 0, "misses": 0, "false_collisions": 0}
    disagreements = []
    for i in range(args.configs):
        p, s = bool(pin_coll[i]), sub_coll[i]
        if p and s:
            counts["both_collide"] += 1
        elif not p and not s:
            counts["both_free"] += 1
        else:
            counts["misses" if p else "false_collisions"] += 1
            a = analyse(ref, qs[i], pin_coll[i], chk["self_pair"][i], sub_pairs, args.tie)
            a.update({"config": i, "kind": "miss" if p else "false collision"})
            disagreements.append(a)
    # The verdicts again on the pairs both sides check.
    common = ref.pairs & sub_pairs
    pin_common = [any(ref.cp_link[k] in common for k in c) for c in pin_coll]
    res["counts"] = counts
    res["pin_colliding_common_pairs"] = sum(pin_common)
    res["pin_colliding_pct"] = 100.0 * sum(map(bool, pin_coll)) / args.configs
    res["sublevel_colliding_pct"] = 100.0 * sum(sub_coll) / args.configs
    res["disagreements"] = disagreements
    res["classes"] = {}
    for a in disagreements:
        key = f"{a['kind']}: {a['class']}"
        res["classes"][key] = res["classes"].get(key, 0) + 1
    log(f"counts {counts}; classes {res['classes']}")
    return res


def table(results: List[dict]) -> str:
    head = ("robot", "dof", "fit s", "links", "pairs sub/pin", "% coll", "misses", "false coll",
            "sub µs/cfg", "pin µs/cfg")
    rows = [head]
    for r in results:
        fit = r.get("fit", {})
        if not fit.get("ok"):
            rows.append((r["robot"], str(r["dof"]), f"{fit.get('seconds', 0):.1f}", "fit failed") + ("",) * 6)
            continue
        pr = r.get("pairs", {})
        if "counts" not in r:
            rows.append((r["robot"], str(r["dof"]), f"{fit['seconds']:.1f}", str(fit.get("links_with_geometry")),
                         f"{pr.get('sublevel_reported')}/{pr.get('pinocchio_link_pairs')}", "check failed",
                         "", "", "", ""))
            continue
        c, chk = r["counts"], r["check"]
        rows.append((
            r["robot"], str(r["dof"]), f"{fit['seconds']:.1f}", str(fit.get("links_with_geometry")),
            f"{pr['sublevel_reported']}/{pr['pinocchio_link_pairs']}",
            f"{r['sublevel_colliding_pct']:.1f}/{r['pin_colliding_pct']:.1f}",
            str(c["misses"]), str(c["false_collisions"]),
            f"{chk.get('us_per_config', float('nan')):.1f}", f"{r['pin_us_per_config']:.1f}"))
    w = [max(len(row[i]) for row in rows) for i in range(len(head))]
    return "\n".join("  ".join(x.rjust(w[i]) if i else x.ljust(w[i]) for i, x in enumerate(row)) for row in rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sublevel", required=True, help="the sublevel binary")
    ap.add_argument("--robots-dir", required=True, type=Path,
                    help="example-robot-data's robots directory (.../cmeel.prefix/share/example-robot-data/robots)")
    ap.add_argument("--package-dir", type=Path, help="ROS package directory for package:// URIs "
                    "(default: the robots directory's grandparent)")
    ap.add_argument("--robot", action="append", required=True, choices=sorted(ROBOTS), help="repeatable")
    ap.add_argument("--configs", type=int, default=2000, help="random configurations per robot (default 2000)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", required=True, type=Path, help="working directory (robot files, CSVs, outputs)")
    ap.add_argument("--json", type=Path, help="write all results here")
    ap.add_argument("--tie", type=float, default=1e-4, help="contact within this distance (m) is a numerical tie")
    ap.add_argument("--fit-timeout", type=float, default=300.0, help="seconds before a fit is stopped (default 300)")
    args = ap.parse_args(argv)
    args.robots_dir = args.robots_dir.resolve()
    args.package_dir = (args.package_dir or args.robots_dir.parent.parent).resolve()
    args.out.mkdir(parents=True, exist_ok=True)

    results = [run_robot(args, name) for name in args.robot]
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))

    print(table(results))
    print("(% coll: Sublevel/pinocchio; pairs: Sublevel's reported 'self pairs checked' / pinocchio's link pairs; "
          "µs per configuration: Sublevel's own report, pinocchio's computeCollisions with FK, stop at first)")
    bad = False
    for r in results:
        fit = r.get("fit", {})
        for w in fit.get("warnings", []):
            print(f"{r['robot']}: fit {w}")
        if "error" in fit:
            print(f"{r['robot']}: FIT FAILED: {fit['error']}")
            bad = True
            continue
        pr = r.get("pairs", {})
        if pr:
            if pr["sublevel_reported"] != pr["sublevel_derived"]:
                print(f"{r['robot']}: Sublevel reports {pr['sublevel_reported']} pairs, its model gives "
                      f"{pr['sublevel_derived']}")
            for p in pr["only_sublevel"]:
                print(f"{r['robot']}: pair only Sublevel checks: {p}")
            for p in pr["only_pinocchio"]:
                print(f"{r['robot']}: pair only pinocchio checks: {p}")
        if "error" in r.get("check", {}):
            print(f"{r['robot']}: CHECK FAILED: {r['check']['error']}")
            bad = True
            continue
        for a in r.get("disagreements", []):
            if a["kind"] == "miss":
                print(f"{r['robot']}: config {a['config']} MISS ({a['class']}): pinocchio collides "
                      f"{'; '.join(f'{k} penetration {v:.3g} m' for k, v in a['pin_colliding_penetration'].items())}")
            else:
                dist = "n/a" if a["distance"] is None else f"{a['distance']:.3g} m"
                print(f"{r['robot']}: config {a['config']} false collision ({a['class']}): Sublevel pair "
                      f"{a['sublevel_pair']}, pinocchio distance {dist}; nearest {a['nearest']} "
                      f"{a['nearest_distance']:.3g} m")
        bad |= r.get("counts", {}).get("misses", 0) > 0
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
