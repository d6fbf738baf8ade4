"""Body files built in Python (the JSON accepted by ``Client.upload_body``).

A body is ``{x : p((x - center) / scale) <= 1}`` with ``p(u, v, w) = Σ coefficients[k] u^a v^b w^c``,
``(a, b, c) = exponents[k]``; center and scale in meters (body frame).
"""

from __future__ import annotations

from typing import Any, Dict, Sequence

import numpy as np

__all__ = ["sphere_body", "ellipsoid_body"]


def ellipsoid_body(radii: Sequence[float], center: Sequence[float] = (0.0, 0.0, 0.0)) -> Dict[str, Any]:
    """The axis-aligned ellipsoid ``Σ ((x_i - c_i) / r_i)² <= 1`` (radii and center in meters) as a
    degree-2 body file (a dict; ``json.dumps`` it or pass it to ``upload_body`` as is)."""
    r = np.asarray(radii, dtype=float)
    c = np.asarray(center, dtype=float)
    if r.shape != (3,) or not np.all(np.isfinite(r)) or np.any(r <= 0):
        raise ValueError(f"`radii`: expected 3 positive finite numbers (meters), got {radii!r}")
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ValueError(f"`center`: expected 3 finite numbers (meters), got {center!r}")
    scale = float(r.max())
    return {
        "degree": 2,
        "exponents": [[2, 0, 0], [0, 2, 0], [0, 0, 2]],
        "coefficients": [float((scale / ri) ** 2) for ri in r],
        "center": [float(x) for x in c],
        "scale": scale,
    }


def sphere_body(radius: float, center: Sequence[float] = (0.0, 0.0, 0.0)) -> Dict[str, Any]:
    """The ball of ``radius`` meters about ``center`` (body frame, meters) as a degree-2 body file:
    exponents ``[[2,0,0],[0,2,0],[0,0,2]]``, coefficients ``[1,1,1]``, scale ``radius``."""
    return ellipsoid_body((radius, radius, radius), center)
