"""The pinocchio + coal side of ``plan_mbm.py``: the robot's collision meshes loaded by the robots
peer's loader (or a minimal one), a mesh state checker and motion validator for OMPL, and the
verifier that re-checks every returned path on the meshes at 1 mm of end-effector travel; and what
both checkers share (the order a sampled motion's states are checked in, the counts).
"""

from __future__ import annotations

import contextlib
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, List, Optional

import numpy as np

REPO = Path(__file__).resolve().parents[3]

if TYPE_CHECKING:
    from plan_mbm import Problem


# -- shared by both checkers ----------------------------------------------------------------------
def van_der_corput(n: int) -> List[int]:
    """1..n ordered so that each next index halves the largest gap left (the end first)."""
    order, seen = [n], {n}
    step = n
    while step > 1:
        step = (step + 1) // 2
        for k in range(step, n, step):
            if k not in seen:
                seen.add(k)
                order.append(k)
    order += [k for k in range(1, n) if k not in seen]
    return order


class Counts:
    """States and motions checked, the seconds spent in the checker, and the paths whose
    certification failed (lazy motions)."""

    def __init__(self):
        self.states = 0
        self.motions = 0
        self.seconds = 0.0
        self.rejected = 0



# -- pinocchio + coal -----------------------------------------------------------------------------
@contextlib.contextmanager
def obj_meshes_as_written(enabled: bool):
    """While active, pinocchio's URDF geometry loader builds each OBJ mesh from the file's own
    vertices and faces (scaled as the URDF says) instead of assimp's reading."""
    import coal
    import pinocchio as pin

    if not enabled:
        yield
        return
    sys.path.insert(0, str(REPO / "scripts" / "peers"))
    try:
        from relabel_panda import read_obj  # an OBJ's own vertices and faces (polygons as fans)
    finally:
        sys.path.pop(0)
    build = pin.buildGeomFromUrdf

    def literal(*a, **k):
        geom = build(*a, **k)
        for g in geom.geometryObjects:
            if g.meshPath and g.meshPath.lower().endswith(".obj"):
                v, t = read_obj(g.meshPath)
                v = v * np.asarray(g.meshScale, dtype=float)
                m = coal.BVHModelOBBRSS()
                m.beginModel(len(t), len(v))
                m.addVertices(v)
                m.addTriangles(t)
                m.endModel()
                g.geometry = m
        return geom

    pin.buildGeomFromUrdf = literal
    try:
        yield
    finally:
        pin.buildGeomFromUrdf = build


def _peer(peer_dir: Optional[Path]):
    """The robots peer's coal_peer module, or None."""
    if not peer_dir or not (Path(peer_dir) / "coal_peer.py").is_file():
        return None
    sys.path.insert(0, str(peer_dir))
    try:
        import coal_peer  # noqa: F401 (the peer's loader)

        return coal_peer
    except ImportError as e:
        print(f"note: {peer_dir}/coal_peer.py does not import ({e}); using the minimal loader", file=sys.stderr)
        return None
    finally:
        sys.path.remove(str(peer_dir))


def _se3(position, quat_xyzw):
    import pinocchio as pin

    x, y, z, w = quat_xyzw if quat_xyzw is not None else (0.0, 0.0, 0.0, 1.0)
    q = pin.Quaternion(w, x, y, z) if (x, y, z, w) != (0, 0, 0, 0) else pin.Quaternion(1, 0, 0, 0)
    q.normalize()
    return pin.SE3(q.matrix(), np.asarray(position, dtype=float))


def _xyz(v):
    return [v["x"], v["y"], v["z"]] if isinstance(v, dict) else list(v)


def _xyzw(v):
    return [v["x"], v["y"], v["z"], v["w"]] if isinstance(v, dict) else list(v)


def minimal_scene(path: str):
    """(objects, allowed pairs) of a MoveIt planning scene's primitives, as the peer's loader reads
    them: boxes (full sides), cylinders ([height, radius]) and spheres at pose · primitive pose."""
    import coal
    import yaml

    data = yaml.safe_load(Path(path).read_text())
    objects = []
    for co in (data.get("world") or {}).get("collision_objects") or []:
        base = _se3(_xyz(co["pose"]["position"]), _xyzw(co["pose"]["orientation"])) if "pose" in co else None
        for k, (prim, pp) in enumerate(zip(co.get("primitives", []), co.get("primitive_poses", []))):
            pose = _se3(_xyz(pp.get("position", [0, 0, 0])), _xyzw(pp.get("orientation", [0, 0, 0, 1])))
            if base is not None:
                pose = base * pose
            d, kind = prim["dimensions"], prim["type"]
            if kind in ("box", 1):
                g = coal.Box(d[0], d[1], d[2])
            elif kind in ("cylinder", 3):
                g = coal.Cylinder(d[1], d[0])
            elif kind in ("sphere", 2):
                g = coal.Sphere(d[0])
            else:
                raise ValueError(f"{path}: unsupported primitive {kind!r}")
            objects.append((f"{co['id']}#{k}", g, pose))
    acm = set()
    m = data.get("allowed_collision_matrix")
    if m:
        names = m["entry_names"]
        for i, row in enumerate(m["entry_values"]):
            row = row["enabled"] if isinstance(row, dict) else row
            acm |= {frozenset((names[i], names[j])) for j, v in enumerate(row) if v and i != j}
    return objects, acm


class MinimalSceneChecker:
    """Every robot geometry against every world object and the robot pairs not allowed, as the
    peer's SceneChecker builds them (used when coal_peer.py cannot be imported)."""

    def __init__(self, model, urdf, package_dir, objects, acm):
        import pinocchio as pin

        self.model, self.data = model, model.createData()
        geom = pin.buildGeomFromUrdf(model, str(urdf), pin.COLLISION, package_dirs=[str(package_dir)])
        n = len(geom.geometryObjects)
        link = [model.frames[g.parentFrame].name for g in geom.geometryObjects]
        for name, g, pose in objects:
            geom.addGeometryObject(pin.GeometryObject(name, 0, 0, pose, g))
        for i in range(n):
            for j in range(n, len(geom.geometryObjects)):
                if frozenset((link[i], geom.geometryObjects[j].name.split("#")[0])) not in acm:
                    geom.addCollisionPair(pin.CollisionPair(i, j))
            for j in range(i + 1, n):
                if link[i] != link[j] and frozenset((link[i], link[j])) not in acm:
                    geom.addCollisionPair(pin.CollisionPair(i, j))
        self.geom, self.gdata = geom, pin.GeometryData(geom)

    def collide(self, q, stop_at_first):
        import pinocchio as pin

        return pin.computeCollisions(self.model, self.data, self.geom, self.gdata, q, stop_at_first)


class MeshChecker:
    """pinocchio + coal on the collision meshes: states by ``computeCollisions`` (stop at the first
    collision), motions sampled at ``resolution`` configurations per unit of joint distance."""

    def __init__(self, urdf: Path, package_dir: Path, joint_names: List[str], disabled: set, peer, obj_as_written: bool, resolution: float):
        import pinocchio as pin

        self.urdf, self.package_dir = urdf, package_dir
        self.model = pin.buildModelFromUrdf(str(urdf))
        self.peer = peer
        self.obj_as_written = obj_as_written
        self.disabled = disabled
        self.resolution = resolution
        self.nq = self.model.nq
        # Where each planning joint sits in pinocchio's q (a continuous joint is cos, sin).
        self.slots = []
        for name in joint_names:
            jid = self.model.getJointId(name)
            if jid >= self.model.njoints:
                raise ValueError(f"pinocchio's model of {urdf} has no joint {name}")
            self.slots.append((self.model.joints[jid].idx_q, self.model.joints[jid].nq))
        self.checker = None
        self.count = Counts()

    def pin_q(self, q: np.ndarray) -> np.ndarray:
        out = np.zeros(self.nq)
        for v, (i, n) in zip(q, self.slots):
            if n == 2:
                out[i], out[i + 1] = math.cos(v), math.sin(v)
            else:
                out[i] = v
        return out

    def set_scene(self, problem: Problem) -> None:
        with tempfile.NamedTemporaryFile(suffix=".yaml") as f:
            f.write(problem.scene)
            f.flush()
            load = self.peer.load_scene if self.peer else minimal_scene
            objects, acm = load(f.name)
        make = self.peer.SceneChecker if self.peer else MinimalSceneChecker
        with obj_meshes_as_written(self.obj_as_written):
            self.checker = make(self.model, self.urdf, self.package_dir, objects, acm | self.disabled)

    def clear_scene(self) -> None:
        self.checker = None

    def collides(self, q: np.ndarray) -> bool:
        return bool(self.checker.collide(self.pin_q(q), True))

    def valid(self, q: np.ndarray) -> bool:
        t0 = time.perf_counter()
        ok = not self.collides(q)
        self.count.seconds += time.perf_counter() - t0
        self.count.states += 1
        return ok

    def motion(self, q0: np.ndarray, q1: np.ndarray) -> bool:
        t0 = time.perf_counter()
        n = max(1, math.ceil(float(np.linalg.norm(q1 - q0)) * self.resolution))
        ok = all(not self.collides(q0 + (k / n) * (q1 - q0)) for k in van_der_corput(n))
        self.count.seconds += time.perf_counter() - t0
        self.count.motions += 1
        return ok


class Verifier:
    """Re-checks paths on the meshes, each edge densified until the end effector moves at most
    ``step`` meters between checked states."""

    def __init__(self, mesh: MeshChecker, ee: Optional[str], step: float):
        import pinocchio as pin

        self.mesh = mesh
        self.step = step
        model = mesh.model
        if ee is None:
            ee = "panda_hand" if model.existFrame("panda_hand") else None
        if ee is None:
            with obj_meshes_as_written(False):
                geom = pin.buildGeomFromUrdf(model, str(mesh.urdf), pin.COLLISION, package_dirs=[str(mesh.package_dir)])
            ee = model.frames[max(g.parentFrame for g in geom.geometryObjects)].name
        if not model.existFrame(ee):
            raise ValueError(f"--ee {ee}: no such link in {mesh.urdf}")
        self.ee = ee
        self.frame = model.getFrameId(ee)
        self.data = model.createData()
        self.corners = None  # the EE's collision geometry's box corners in its frame, set per scene

    def _points(self, q: np.ndarray) -> np.ndarray:
        import pinocchio as pin

        pin.framesForwardKinematics(self.mesh.model, self.data, self.mesh.pin_q(q))
        m = self.data.oMf[self.frame]
        return self.corners @ m.rotation.T + m.translation

    def _set_corners(self) -> None:
        geom = self.mesh.checker.geom
        pts = [np.zeros(3)]
        for g in geom.geometryObjects:
            if g.parentFrame == self.frame:
                g.geometry.computeLocalAABB()
                lo, hi = np.asarray(g.geometry.aabb_local.min_), np.asarray(g.geometry.aabb_local.max_)
                box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
                pts.append(box @ np.asarray(g.placement.rotation).T + np.asarray(g.placement.translation))
        self.corners = np.vstack([np.atleast_2d(p) for p in pts])

    def edge_ts(self, q0: np.ndarray, q1: np.ndarray) -> List[float]:
        """Parameters t in [0, 1] of the states checked on q0 -> q1: consecutive ones move every
        tracked point of the end effector at most ``step`` (chord) apart."""
        ts = list(np.linspace(0.0, 1.0, 9))
        pts = [self._points(q0 + t * (q1 - q0)) for t in ts]
        k = 0
        while k < len(ts) - 1:
            if np.max(np.linalg.norm(pts[k + 1] - pts[k], axis=1)) > self.step and ts[k + 1] - ts[k] > 1e-12:
                t = 0.5 * (ts[k] + ts[k + 1])
                ts.insert(k + 1, t)
                pts.insert(k + 1, self._points(q0 + t * (q1 - q0)))
            else:
                k += 1
        return ts

    def check_path(self, path: List[np.ndarray]):
        """(states checked, the first colliding (edge, t) or None)."""
        self._set_corners()
        checked = 0
        for e in range(len(path) - 1):
            for t in self.edge_ts(path[e], path[e + 1]):
                if e > 0 and t == 0.0:
                    continue
                checked += 1
                if self.mesh.collides(path[e] + t * (path[e + 1] - path[e])):
                    return checked, (e, t)
        return checked, None


# -- planning -------------------------------------------------------------------------------------
