"""Rigid poses: unit quaternion (w, x, y, z) + translation in meters.

A pose maps body-frame points to world points, ``x_world = R @ x_body + t``. Every function here
accepts a pose in any of three forms (see :func:`as_pose`):

* ``Pose(quat=(w, x, y, z), t=(x, y, z))``,
* a 7-vector ``[w, x, y, z, tx, ty, tz]`` (list, tuple or numpy array),
* a 4x4 homogeneous matrix ``[[R, t], [0, 0, 0, 1]]`` (numpy array or nested lists).

Quaternions are passed to the server as given: the server requires a unit norm within 1e-6 and
answers INVALID_ARGUMENT otherwise (it never renormalizes silently). Quaternions computed here from
rotation matrices are unit to machine precision, with w >= 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Tuple, Union

import numpy as np

__all__ = [
    "Pose",
    "PoseLike",
    "as_pose",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_multiply",
    "quat_from_axis_angle",
]

#: Tolerance of the orthonormality check of a rotation matrix (max abs entry of RᵀR − I).
ROTATION_TOLERANCE = 1e-6


def _vec(value: Any, n: int, name: str) -> Tuple[float, ...]:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"`{name}`: expected {n} numbers, got {value!r} ({e})") from None
    if a.shape != (n,):
        raise ValueError(f"`{name}`: expected shape ({n},), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"`{name}`: expected finite numbers, got {a.tolist()}")
    return tuple(float(x) for x in a)


@dataclass(frozen=True)
class Pose:
    """A rigid pose.

    Attributes:
        quat: rotation as a unit quaternion ``(w, x, y, z)`` (scalar first).
        t: translation ``(x, y, z)`` in meters.
    """

    quat: Tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    t: Tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "quat", _vec(self.quat, 4, "quat"))
        object.__setattr__(self, "t", _vec(self.t, 3, "t"))

    # -- constructors -----------------------------------------------------------------------
    @classmethod
    def identity(cls) -> "Pose":
        """The identity pose."""
        return cls()

    @classmethod
    def from_vector(cls, v: Any, name: str = "pose") -> "Pose":
        """From ``[w, x, y, z, tx, ty, tz]`` (quaternion, then translation in meters)."""
        a = _vec(v, 7, name)
        return cls(quat=a[:4], t=a[4:])

    @classmethod
    def from_matrix(cls, m: Any, name: str = "pose") -> "Pose":
        """From a 4x4 homogeneous matrix ``[[R, t], [0, 0, 0, 1]]`` (t in meters).

        Raises ValueError (naming ``name``) unless R is a proper rotation (RᵀR = I within 1e-6,
        det R > 0) and the last row is ``[0, 0, 0, 1]``.
        """
        a = np.asarray(m, dtype=float)
        if a.shape != (4, 4):
            raise ValueError(f"`{name}`: expected a 4x4 homogeneous matrix, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"`{name}`: the matrix has non-finite entries")
        if not np.allclose(a[3], [0.0, 0.0, 0.0, 1.0], atol=1e-12, rtol=0.0):
            raise ValueError(f"`{name}`: the last row of a homogeneous matrix must be [0, 0, 0, 1], got {a[3].tolist()}")
        return cls(quat=matrix_to_quat(a[:3, :3], name=name), t=a[:3, 3])

    @classmethod
    def from_rotation(cls, R: Any, t: Any = (0.0, 0.0, 0.0), name: str = "pose") -> "Pose":
        """From a 3x3 rotation matrix and a translation in meters."""
        return cls(quat=matrix_to_quat(R, name=name), t=_vec(t, 3, name + ".t"))

    # -- views ------------------------------------------------------------------------------
    @property
    def rotation(self) -> np.ndarray:
        """The 3x3 rotation matrix R of :attr:`quat`."""
        return quat_to_matrix(self.quat)

    @property
    def translation(self) -> np.ndarray:
        """The translation as a numpy array of shape (3,), meters."""
        return np.array(self.t)

    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous matrix ``[[R, t], [0, 0, 0, 1]]``."""
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.t
        return m

    def vector(self) -> np.ndarray:
        """``[w, x, y, z, tx, ty, tz]`` as a numpy array of shape (7,)."""
        return np.array(self.quat + self.t)

    def apply(self, points: Any) -> np.ndarray:
        """Maps body-frame points (shape (3,) or (n, 3), meters) to world points."""
        p = np.asarray(points, dtype=float)
        return p @ self.rotation.T + np.asarray(self.t)

    def __matmul__(self, other: "Pose") -> "Pose":
        """Composition: ``(self @ other).apply(x) == self.apply(other.apply(x))``."""
        other = as_pose(other, "other")
        q = quat_multiply(self.quat, other.quat)
        return Pose(quat=q, t=self.apply(other.t))

    def inverse(self) -> "Pose":
        """The inverse pose."""
        w, x, y, z = self.quat
        qi = (w, -x, -y, -z)
        Rt = self.rotation.T
        return Pose(quat=qi, t=-(Rt @ np.asarray(self.t)))


PoseLike = Union[Pose, np.ndarray, "list[float]", "tuple[float, ...]", "list[list[float]]"]


def as_pose(value: Any, name: str = "pose") -> Pose:
    """Converts a pose given as a :class:`Pose`, a 7-vector ``[w, x, y, z, tx, ty, tz]`` or a 4x4
    homogeneous matrix; ``None`` means the identity.

    Raises ValueError naming ``name`` when the shape or the values are wrong.
    """
    if value is None:
        return Pose()
    if isinstance(value, Pose):
        return value
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f"`{name}`: expected a Pose, a 7-vector [w, x, y, z, tx, ty, tz] or a 4x4 matrix, got {value!r}"
        ) from None
    if a.shape == (7,):
        return Pose.from_vector(a, name)
    if a.shape == (4, 4):
        return Pose.from_matrix(a, name)
    raise ValueError(
        f"`{name}`: expected a Pose, a 7-vector [w, x, y, z, tx, ty, tz] or a 4x4 matrix, got shape {a.shape}"
    )


def quat_to_matrix(q: Any) -> np.ndarray:
    """Rotation matrix of a quaternion ``(w, x, y, z)``; the quaternion is normalized first."""
    w, x, y, z = _vec(q, 4, "quat")
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if n == 0.0:
        raise ValueError("`quat`: the zero quaternion is not a rotation")
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat(R: Any, name: str = "rotation") -> Tuple[float, float, float, float]:
    """Unit quaternion ``(w, x, y, z)`` with ``w >= 0`` of a 3x3 rotation matrix (Shepperd's method).

    Raises ValueError naming ``name`` unless R is orthonormal within 1e-6 with det R > 0.
    """
    a = np.asarray(R, dtype=float)
    if a.shape != (3, 3):
        raise ValueError(f"`{name}`: expected a 3x3 rotation matrix, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"`{name}`: the rotation has non-finite entries")
    err = float(np.max(np.abs(a.T @ a - np.eye(3))))
    if err > ROTATION_TOLERANCE or np.linalg.det(a) <= 0.0:
        raise ValueError(
            f"`{name}`: not a rotation matrix (max |RᵀR − I| = {err:.2e}, det = {np.linalg.det(a):.6g})"
        )
    tr = a[0, 0] + a[1, 1] + a[2, 2]
    if tr > 0.0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = (0.25 * s, (a[2, 1] - a[1, 2]) / s, (a[0, 2] - a[2, 0]) / s, (a[1, 0] - a[0, 1]) / s)
    elif a[0, 0] > a[1, 1] and a[0, 0] > a[2, 2]:
        s = 2.0 * math.sqrt(1.0 + a[0, 0] - a[1, 1] - a[2, 2])
        q = ((a[2, 1] - a[1, 2]) / s, 0.25 * s, (a[0, 1] + a[1, 0]) / s, (a[0, 2] + a[2, 0]) / s)
    elif a[1, 1] > a[2, 2]:
        s = 2.0 * math.sqrt(1.0 + a[1, 1] - a[0, 0] - a[2, 2])
        q = ((a[0, 2] - a[2, 0]) / s, (a[0, 1] + a[1, 0]) / s, 0.25 * s, (a[1, 2] + a[2, 1]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + a[2, 2] - a[0, 0] - a[1, 1])
        q = ((a[1, 0] - a[0, 1]) / s, (a[0, 2] + a[2, 0]) / s, (a[1, 2] + a[2, 1]) / s, 0.25 * s)
    v = np.array(q)
    v /= np.linalg.norm(v)
    if v[0] < 0.0:
        v = -v
    return tuple(float(x) for x in v)  # type: ignore[return-value]


def quat_multiply(p: Any, q: Any) -> Tuple[float, float, float, float]:
    """Hamilton product ``p ⊗ q`` of quaternions ``(w, x, y, z)`` (rotation q first, then p)."""
    w1, x1, y1, z1 = _vec(p, 4, "p")
    w2, x2, y2, z2 = _vec(q, 4, "q")
    return (
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    )


def quat_from_axis_angle(axis: Any, angle: float) -> Tuple[float, float, float, float]:
    """Unit quaternion ``(w, x, y, z)`` of a rotation by ``angle`` radians about ``axis``."""
    a = np.asarray(_vec(axis, 3, "axis"))
    n = np.linalg.norm(a)
    if n == 0.0:
        raise ValueError("`axis`: must be nonzero")
    a = a / n
    s = math.sin(angle / 2.0)
    return (math.cos(angle / 2.0), float(a[0] * s), float(a[1] * s), float(a[2] * s))
