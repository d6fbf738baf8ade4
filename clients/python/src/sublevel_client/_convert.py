"""Message fields to numpy arrays and poses: the parsers shared by the answer types."""

from __future__ import annotations

from typing import Dict, Optional

import numpy as np

from .poses import Pose


def _v3(m) -> np.ndarray:
    return np.array([m.x, m.y, m.z], dtype=float)


def _twist(msg, has: bool) -> Optional[np.ndarray]:
    if not has:
        return None
    return np.concatenate([_v3(msg.linear), _v3(msg.angular)])


def _pose(m, has: bool) -> Pose:
    if not has:
        return Pose()
    q = (m.rotation.w, m.rotation.x, m.rotation.y, m.rotation.z) if m.HasField("rotation") else (1.0, 0.0, 0.0, 0.0)
    t = (m.translation.x, m.translation.y, m.translation.z) if m.HasField("translation") else (0.0, 0.0, 0.0)
    return Pose(quat=q, t=t)


def _enum_name(enum_type, value: int, prefix: str) -> str:
    try:
        name = enum_type.Name(value)
    except ValueError:
        return str(value)
    return name[len(prefix):] if name.startswith(prefix) else name



def _primitive_dict(m) -> Dict[str, object]:
    """A ``Primitive`` message as the keys ``Client.check_configurations`` takes for an attached
    object: ``kind`` and its dimensions (meters)."""
    from ._pb.sublevel.v1 import sublevel_pb2 as pb

    kind = _enum_name(pb.PrimitiveKind, m.kind, "PRIMITIVE_KIND_").lower()
    if kind == "box":
        return {"kind": kind, "size": tuple(float(x) for x in m.size)}
    if kind == "sphere":
        return {"kind": kind, "radius": m.radius}
    if kind in ("cylinder", "capsule"):
        return {"kind": kind, "radius": m.radius, "height": m.height}
    return {"kind": kind}



def _columns(values, count: int, width: int) -> np.ndarray:
    """A repeated double field as a (count, width) array; all NaN when the server sent none."""
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return np.full((count, width), np.nan)
    return a.reshape(count, width)
