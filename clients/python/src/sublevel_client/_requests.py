"""Request building shared by :class:`~sublevel_client.Client` and
:class:`~sublevel_client.PlannerStream`: queries, instance poses, joint configurations, primitives and
attached objects as messages, each argument checked (ValueError naming it) before anything is sent.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from ._pb.sublevel.v1 import sublevel_pb2 as pb
from .poses import as_pose


# Metadata key naming the scene of a call, for scene-sharding proxies (deploy/SCALING.md).
SCENE_ID_HEADER = "x-scene-id"

#: The demo server's address (``cargo run --release -- serve --demo``).
DEFAULT_ADDR = "127.0.0.1:50051"

_KINDS = {
    "distance": pb.QUERY_KIND_DISTANCE,
    "growth": pb.QUERY_KIND_GROWTH,
    "collide": pb.QUERY_KIND_COLLIDE,
}

PosesLike = Union[Mapping[str, Any], Iterable[Tuple[str, Any]], None]


@dataclass(frozen=True)
class Query:
    """One query between two instances of a scene.

    Attributes:
        kind: "distance" (Euclidean distance, meters), "growth" (d(first || second),
            dimensionless) or "collide" (closer than ``margin`` meters, or overlapping?).
        first, second: instance ids (A and B; p1 and p2 for growth).
        margin: for "collide": the margin in meters (>= 0; 0 asks "do they overlap?").
        certify: also solve the level-0 SDP certificate (milliseconds to seconds).
        with_gradient: also return pose gradients (distance and growth).
        cold: on a stream: ignore this pair's warm start and leave none behind.
        signed: "distance" only: also the signed distance (penetration depth when overlapping).
    """

    kind: str
    first: str
    second: str
    margin: float = 0.0
    certify: bool = False
    with_gradient: bool = False
    cold: bool = False
    signed: bool = False

    @classmethod
    def distance(
        cls, a: str, b: str, *, certify: bool = False, with_gradient: bool = False, cold: bool = False, signed: bool = False
    ) -> "Query":
        """Euclidean distance between instances ``a`` and ``b`` (meters); ``signed`` also asks
        for the signed distance (minus the penetration depth when overlapping)."""
        return cls("distance", a, b, certify=certify, with_gradient=with_gradient, cold=cold, signed=signed)

    @classmethod
    def growth(cls, p1: str, p2: str, *, certify: bool = False, with_gradient: bool = False, cold: bool = False) -> "Query":
        """Growth measure d(p1 || p2) = min p1(x) s.t. p2(x) <= 1 (> 1 iff separated)."""
        return cls("growth", p1, p2, certify=certify, with_gradient=with_gradient, cold=cold)

    @classmethod
    def collide(cls, a: str, b: str, margin: float = 0.0, *, cold: bool = False) -> "Query":
        """Are ``a`` and ``b`` closer than ``margin`` meters (or overlapping)?"""
        return cls("collide", a, b, margin=margin, cold=cold)


def as_query(q: Any, name: str = "query") -> Query:
    """A :class:`Query`, or a tuple ``(kind, first, second)`` / ``(kind, first, second, margin)``."""
    if isinstance(q, Query):
        out = q
    elif isinstance(q, (tuple, list)) and len(q) in (3, 4):
        out = Query(str(q[0]), q[1], q[2], float(q[3]) if len(q) == 4 else 0.0)
    else:
        raise ValueError(f"`{name}`: expected a Query or a tuple (kind, first, second[, margin]), got {q!r}")
    if out.kind not in _KINDS:
        raise ValueError(f"`{name}.kind`: expected one of {sorted(_KINDS)}, got {out.kind!r}")
    if out.signed and out.kind != "distance":
        raise ValueError(f"`{name}.signed`: only distance queries have a signed distance")
    if not isinstance(out.first, str) or not isinstance(out.second, str):
        raise ValueError(f"`{name}`: instance ids must be strings, got {out.first!r}, {out.second!r}")
    return out


def _pose_pb(pose: Any, name: str) -> pb.Pose:
    p = as_pose(pose, name)
    w, x, y, z = p.quat
    return pb.Pose(rotation=pb.Quaternion(w=w, x=x, y=y, z=z), translation=pb.Vec3(x=p.t[0], y=p.t[1], z=p.t[2]))


def _instance_poses(poses: PosesLike, name: str) -> List[pb.InstancePose]:
    if poses is None:
        return []
    items = poses.items() if isinstance(poses, Mapping) else poses
    out = []
    for item in items:
        try:
            instance_id, pose = item
        except (TypeError, ValueError):
            raise ValueError(f"`{name}`: expected a mapping {{instance_id: pose}} or (instance_id, pose) pairs") from None
        if not isinstance(instance_id, str):
            raise ValueError(f"`{name}`: instance ids must be strings, got {instance_id!r}")
        out.append(pb.InstancePose(instance_id=instance_id, pose=_pose_pb(pose, f"{name}[{instance_id}]")))
    return out


def _planner_queries(queries: Iterable[Any]) -> List[pb.PlannerQuery]:
    if isinstance(queries, (Query, str)):
        raise ValueError("`queries`: expected a list of queries")
    out = []
    for k, q in enumerate(queries):
        q = as_query(q, f"queries[{k}]")
        out.append(
            pb.PlannerQuery(
                kind=_KINDS[q.kind],
                first=q.first,
                second=q.second,
                certify=q.certify,
                with_gradient=q.with_gradient,
                margin=float(q.margin),
                cold=q.cold,
                signed=q.signed,
            )
        )
    return out


def _pair_columns(
    kind: str, first: Sequence[str], second: Sequence[str], margin: float, cold: bool = False
) -> pb.PairColumns:
    """``PairColumns`` of the pairs (first[k], second[k]): each id sent once, pairs as indices;
    ``cold`` asks for cold answers (no warm start read or kept)."""
    if kind not in _KINDS:
        raise ValueError(f"`kind`: must be one of {sorted(_KINDS)}, got {kind!r}")
    first, second = list(first), list(second)
    if len(first) != len(second):
        raise ValueError(f"`second`: {len(second)} ids, `first` has {len(first)}")
    index: dict = {}
    for i in first + second:
        index.setdefault(i, len(index))
    return pb.PairColumns(
        kind=_KINDS[kind],
        instance_ids=list(index),
        first=[index[i] for i in first],
        second=[index[i] for i in second],
        margin=float(margin),
        cold=bool(cold),
    )


def _state_columns(instance_ids: Sequence[str], poses: Any) -> pb.StateColumns:
    """``StateColumns`` of candidate states given as an array ``poses`` of shape (S, n, 7) (or
    (S, 7) for one instance): per state and instance of ``instance_ids``, the unit quaternion w, x,
    y, z and the translation x, y, z in meters."""
    ids = [instance_ids] if isinstance(instance_ids, str) else list(instance_ids)
    if not ids or not all(isinstance(i, str) for i in ids):
        raise ValueError(f"`instance_ids`: expected one or more instance id strings, got {instance_ids!r}")
    arr = np.asarray(poses, dtype=float)
    if arr.ndim == 2 and len(ids) == 1:
        arr = arr[:, None, :]
    if arr.ndim != 3 or arr.shape[1:] != (len(ids), 7) or arr.shape[0] == 0:
        raise ValueError(
            f"`poses`: expected shape (states, {len(ids)}, 7) (w, x, y, z, tx, ty, tz per instance), got {arr.shape}"
        )
    return pb.StateColumns(instance_ids=ids, poses=arr.ravel().tolist())


def _motion_poses(poses: Any, count: int, name: str) -> np.ndarray:
    """The poses of ``count`` motions as an array of shape (count, 7) (w, x, y, z, tx, ty, tz);
    a (7,) array for one motion."""
    arr = np.asarray(poses, dtype=float)
    if arr.ndim == 1 and count == 1:
        arr = arr[None, :]
    if arr.shape != (count, 7):
        raise ValueError(f"`{name}`: expected shape ({count}, 7) (w, x, y, z, tx, ty, tz per motion), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}`: expected finite numbers")
    return arr


def _state_columns_query(
    scene: str, kind: str, first: Sequence[str], second: Sequence[str], instance_ids: Sequence[str], state_poses: Any,
    margin: float = 0.0, poses: PosesLike = None, cold: bool = False,
) -> pb.QueryRequest:
    """The ``QueryRequest`` of :meth:`PlannerStream.check_state_columns` (same arguments)."""
    return pb.QueryRequest(
        scene_id=scene,
        poses=_instance_poses(poses, "poses"),
        columns=_pair_columns(kind, first, second, margin, cold),
        state_columns=_state_columns(instance_ids, state_poses),
    )


def _states(states: Optional[Iterable[PosesLike]]) -> List[pb.CandidateState]:
    if states is None:
        return []
    return [pb.CandidateState(poses=_instance_poses(s, f"states[{k}]")) for k, s in enumerate(states)]


def _body_json(body: Any) -> str:
    if isinstance(body, Mapping):
        return json.dumps(body)
    if isinstance(body, bytes):
        return body.decode("utf-8")
    if isinstance(body, os.PathLike):
        with open(body, encoding="utf-8") as f:
            return f.read()
    if isinstance(body, str):
        if body.lstrip().startswith("{"):
            return body
        if os.path.isfile(body):
            with open(body, encoding="utf-8") as f:
                return f.read()
        raise ValueError(f"`body`: neither JSON text nor an existing file: {body[:80]!r}")
    raise ValueError(f"`body`: expected JSON text, a path or a dict, got {type(body).__name__}")


def _robot_file(robot_file: Any) -> bytes:
    """The bytes of a robot file given as a path (``str`` or ``os.PathLike``), bytes, or JSON text."""
    if isinstance(robot_file, (bytes, bytearray, memoryview)):
        return bytes(robot_file)
    if isinstance(robot_file, os.PathLike) or (isinstance(robot_file, str) and os.path.isfile(robot_file)):
        return Path(robot_file).read_bytes()
    if isinstance(robot_file, str):
        if robot_file.lstrip().startswith("{"):
            return robot_file.encode("utf-8")
        raise ValueError(f"`robot_file`: neither an existing file nor JSON text: {robot_file[:80]!r}")
    raise ValueError(f"`robot_file`: expected a path or bytes, got {type(robot_file).__name__}")


def _joint_names(joint_names: Optional[Sequence[str]]) -> List[str]:
    if joint_names is None:
        return []
    if isinstance(joint_names, str):
        raise ValueError(f"`joint_names`: expected a list of joint names, got the string {joint_names!r}")
    names = list(joint_names)
    if not all(isinstance(j, str) for j in names):
        raise ValueError(f"`joint_names`: expected strings, got {names!r}")
    if len(set(names)) != len(names):
        raise ValueError(f"`joint_names`: each joint at most once, got {names!r}")
    return names


def _configurations(q: Any, n: int, name: str, what: str) -> np.ndarray:
    """``q`` as a (count, n) float array: a 2-D array-like of shape (count, n), or one
    configuration of shape (n,). ValueError naming ``name`` on another shape, no rows, or a
    non-finite entry; ``what`` says where n comes from."""
    try:
        a = np.asarray(q, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"`{name}`: expected an array of joint values, got {q!r} ({e})") from None
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != n:
        raise ValueError(f"`{name}`: expected shape (configurations, {n}) or ({n},) ({what}), got shape {np.shape(q)}")
    if a.shape[0] == 0:
        raise ValueError(f"`{name}`: no configuration")
    bad = np.argwhere(~np.isfinite(a))
    if len(bad):
        c, k = bad[0]
        raise ValueError(f"`{name}`: entry [{c}, {k}] is not finite ({a[c, k]})")
    return a


def _configuration_columns(values: np.ndarray, joint_names: List[str]) -> pb.ConfigurationColumns:
    return pb.ConfigurationColumns(joint_names=joint_names, values=np.ascontiguousarray(values).ravel().tolist())


def _joint_positions(positions: Any, name: str) -> pb.ConfigurationColumns:
    """One configuration from a mapping ``{joint name: value}`` (radians or meters), in the
    mapping's order. ValueError naming ``name`` (``name[joint]`` for a value) when it is not a
    mapping of strings to finite numbers."""
    if not isinstance(positions, Mapping):
        raise ValueError(f"`{name}`: expected a mapping {{joint name: value}}, got {type(positions).__name__}")
    names, values = [], []
    for joint, value in positions.items():
        if not isinstance(joint, str):
            raise ValueError(f"`{name}`: joint names must be strings, got {joint!r}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"`{name}[{joint}]`: expected a number, got {value!r}") from None
        if not math.isfinite(v):
            raise ValueError(f"`{name}[{joint}]`: not finite ({v})")
        names.append(joint)
        values.append(v)
    return pb.ConfigurationColumns(joint_names=names, values=values)


FIDELITY_LEVELS = ("mesh", "bodies", "spheres")


def _fidelity_pb(fidelity: Optional[str], sphere_tolerance: float = 0.0) -> "Optional[pb.Fidelity]":
    """The ``Fidelity`` message of a request: None (or "mesh" with no tolerance) sends none (the
    meshes' level). ValueError naming ``fidelity`` or ``sphere_tolerance`` for an unknown level or
    a tolerance that is not a number >= 0 (the server checks its range, naming
    ``fidelity.tolerance``)."""
    level = "mesh" if fidelity is None else fidelity
    if not isinstance(level, str) or level.strip().lower() not in FIDELITY_LEVELS:
        raise ValueError(f"`fidelity`: expected one of {', '.join(FIDELITY_LEVELS)}, got {fidelity!r}")
    tolerance = float(sphere_tolerance)
    if not math.isfinite(tolerance) or tolerance < 0.0:
        raise ValueError(f"`sphere_tolerance`: expected meters >= 0 (0: the default), got {sphere_tolerance!r}")
    level = level.strip().lower()
    if level == "mesh" and tolerance == 0.0:
        return None
    return pb.Fidelity(level=level, tolerance=tolerance)


def _link_padding(link_padding: Optional[Mapping[str, float]]) -> dict:
    return {str(k): float(v) for k, v in (link_padding or {}).items()}


def _primitive_pb(kind: str, *, size=None, radius=None, height=None, normal=None, offset=None) -> "pb.Primitive":
    """A ``Primitive`` message (see :meth:`Client.upload_primitive` for the kinds and dimensions).
    Raises ValueError for an unknown kind or a normal that is not 3 numbers."""
    kinds = {
        "box": pb.PRIMITIVE_KIND_BOX,
        "sphere": pb.PRIMITIVE_KIND_SPHERE,
        "cylinder": pb.PRIMITIVE_KIND_CYLINDER,
        "capsule": pb.PRIMITIVE_KIND_CAPSULE,
        "halfspace": pb.PRIMITIVE_KIND_HALFSPACE,
    }
    if kind not in kinds:
        raise ValueError(f"`kind`: one of {', '.join(kinds)}, got {kind!r}")
    p = pb.Primitive(kind=kinds[kind])
    if size is not None:
        p.size.extend(float(x) for x in size)
    if radius is not None:
        p.radius = float(radius)
    if height is not None:
        p.height = float(height)
    if normal is not None:
        n = [float(x) for x in normal]
        if len(n) != 3:
            raise ValueError(f"`normal`: expected 3 numbers, got {len(n)}")
        p.normal.CopyFrom(pb.Vec3(x=n[0], y=n[1], z=n[2]))
    if offset is not None:
        p.offset = float(offset)
    return p


def _attached_one(a: Any, name: str) -> "pb.AttachedObject":
    """One ``AttachedObject`` message from a dict ``{"link", "name", "kind", size / radius /
    height, "origin"}`` (origin: a pose as ``base`` takes it, default identity). Raises ValueError
    naming ``name``."""
    if not isinstance(a, Mapping) or "link" not in a or "kind" not in a:
        raise ValueError(f"`{name}`: a dict with `link`, `kind` and its dimensions")
    dims = {d: a[d] for d in ("size", "radius", "height") if a.get(d) is not None}
    msg = pb.AttachedObject(link=str(a["link"]), name=str(a.get("name", "")),
                            primitive=_primitive_pb(a["kind"], **dims))
    if a.get("origin") is not None:
        msg.origin.CopyFrom(_pose_pb(a["origin"], f"{name}.origin"))
    return msg


def _attached_pb(attached) -> List["pb.AttachedObject"]:
    """``AttachedObject`` messages from dicts (see :func:`_attached_one`). Raises ValueError
    naming ``attached[k]``."""
    return [_attached_one(a, f"attached[{k}]") for k, a in enumerate(attached or ())]
