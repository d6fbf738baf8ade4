"""The point-cloud calls of :class:`~sublevel_client.Client`: obstacles from depth sensors set in a
scene from numpy points or a depth image (``UpdatePointCloud``), and removed.

A scene holds up to 16 named clouds. Each kept point is a ball of the cloud's noise radius in the
world frame, and every robot check of the scene (``check_configurations``, ``check_motions``,
``plan``, ``check_scene``) sees it as a world object named by the cloud's name. Clouds are sensor
data: the server keeps them in memory only, so a restarted server (or another replica) has none
until the next frame is sent. Units: meters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional, Sequence, Tuple

import numpy as np

from ._pb.sublevel.v1 import sublevel_pb2 as pb
from ._requests import _pose_pb

__all__ = ["CloudCalls", "FilterCounts", "PointCloudInfo", "PointCloudUpdate"]

_COUNTS = ("input", "holes", "range", "workspace", "voxel", "outliers", "robot", "kept")


@dataclass(frozen=True)
class FilterCounts:
    """What a frame's filters did, in points.

    Attributes:
        input: points in the frame (a depth image: width × height).
        holes: a coordinate NaN or infinite, or a pixel without a depth (0, NaN).
        range: outside ``[min_range, max_range]`` of the sensor.
        workspace: outside the workspace box.
        voxel: merged into another point of their voxel.
        outliers: statistical outliers.
        robot: within the self filter's padding of the scene's robot.
        kept: points kept (the cloud's size).
    """

    input: int = 0
    holes: int = 0
    range: int = 0
    workspace: int = 0
    voxel: int = 0
    outliers: int = 0
    robot: int = 0
    kept: int = 0

    @classmethod
    def from_proto(cls, m) -> "FilterCounts":
        return cls(**{k: int(getattr(m, k)) for k in _COUNTS})


@dataclass(frozen=True)
class CloudBodiesReport:
    """What the bodies model did with a frame (``model="bodies"``).

    Attributes:
        clusters: clusters of the frame, each one convex sos body.
        outliers: points dropped as outliers (in clusters under ``min_points``).
        reused: clusters whose previous body still contains every new point ball (kept).
        rescaled: clusters whose previous body was rescaled to contain them, with no fit.
        fitted: clusters fitted (new, or grown past the rescale limit).
        fallbacks: fits that failed and got a bounding ball.
        cluster_seconds: the server's time clustering.
        fit_seconds: the server's time on reuse checks, rescales and fits.
    """

    clusters: int
    outliers: int
    reused: int
    rescaled: int
    fitted: int
    fallbacks: int
    cluster_seconds: float
    fit_seconds: float

    @classmethod
    def from_proto(cls, m) -> "CloudBodiesReport":
        return cls(
            clusters=int(m.clusters),
            outliers=int(m.outliers),
            reused=int(m.reused),
            rescaled=int(m.rescaled),
            fitted=int(m.fitted),
            fallbacks=int(m.fallbacks),
            cluster_seconds=float(m.cluster_seconds),
            fit_seconds=float(m.fit_seconds),
        )


@dataclass(frozen=True)
class PointCloudUpdate:
    """The answer of :meth:`CloudCalls.update_point_cloud`.

    Attributes:
        scene_version: the scene version the update produced; a check whose ``scene_version`` is
            at least this one saw this frame (or a later one).
        counts: what the filters did (:class:`FilterCounts`).
        memory_bytes: bytes the cloud holds on the server.
        seconds: the server's time on the frame (decoding, filters, k-d tree, bodies).
        bodies: what the bodies model did (:class:`CloudBodiesReport`); None for the points
            model.
    """

    scene_version: int
    counts: FilterCounts
    memory_bytes: int
    seconds: float
    bodies: Optional[CloudBodiesReport] = None


@dataclass(frozen=True)
class PointCloudInfo:
    """A point cloud of a scene, as :meth:`Client.get_scene` lists it.

    Attributes:
        name: its name.
        points: points kept.
        noise_radius: the radius of every point's ball (meters).
        memory_bytes: bytes it holds on the server.
        version: the scene version its update produced.
        counts: what the filters of its frame did.
        model: ``"points"`` or ``"bodies"``.
        bodies: its bodies (0 for the points model).
    """

    name: str
    points: int
    noise_radius: float
    memory_bytes: int
    version: int
    counts: FilterCounts
    model: str = "points"
    bodies: int = 0

    @classmethod
    def from_proto(cls, m) -> "PointCloudInfo":
        return cls(
            name=m.name,
            points=int(m.points),
            noise_radius=float(m.noise_radius),
            memory_bytes=int(m.memory_bytes),
            version=int(m.version),
            counts=FilterCounts.from_proto(m.counts),
            model="bodies" if m.model == pb.CLOUD_MODEL_BODIES else "points",
            bodies=int(m.bodies),
        )


def _meters(value: Any, name: str, *, positive: bool = False) -> float:
    """A finite number of meters (>= 0, or > 0 with ``positive``); ValueError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}`: expected a number of meters, got {value!r}") from None
    if not math.isfinite(v) or v < 0.0 or (positive and v == 0.0):
        raise ValueError(f"`{name}`: expected a finite number {'>' if positive else '>='} 0, got {value!r}")
    return v


def _packed_points(points: Any) -> pb.PackedPoints:
    """An (N, 3) array of points (sensor frame, meters) as tightly packed little-endian float32
    x, y, z; NaN rows are holes the server counts."""
    a = np.asarray(points)
    if a.ndim != 2 or a.shape[1] != 3 or not (a.dtype.kind in "fiu"):
        raise ValueError(f"`points`: expected an (N, 3) array of numbers (meters), got shape {a.shape} of {a.dtype}")
    return pb.PackedPoints(data=np.ascontiguousarray(a, dtype="<f4").tobytes(), point_step=12)


def _depth_image(depth: Any, fx: Any, fy: Any, cx: Any, cy: Any, depth_scale: float) -> pb.DepthImage:
    """An (H, W) depth image (uint16 in units of ``depth_scale`` meters, or float meters) with its
    pinhole intrinsics."""
    a = np.asarray(depth)
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"`depth`: expected an (H, W) image, got shape {a.shape}")
    for name, v in (("fx", fx), ("fy", fy), ("cx", cx), ("cy", cy)):
        if v is None:
            raise ValueError(f"`{name}`: required with `depth` (pinhole intrinsics, pixels)")
    h, w = a.shape
    m = pb.DepthImage(width=w, height=h, fx=float(fx), fy=float(fy), cx=float(cx), cy=float(cy))
    if a.dtype == np.uint16:
        m.depth_u16 = np.ascontiguousarray(a, dtype="<u2").tobytes()
        m.depth_scale = _meters(depth_scale, "depth_scale", positive=True)
    elif a.dtype.kind == "f":
        m.depth_f32 = np.ascontiguousarray(a, dtype="<f4").tobytes()
    else:
        raise ValueError(f"`depth`: expected uint16 (units of depth_scale) or float (meters) pixels, got {a.dtype}")
    return m


def _cloud_filter(
    *,
    min_range: float,
    max_range: float,
    voxel: float,
    workspace: Any,
    outliers: Any,
    self_filter: bool,
    self_filter_padding: float,
) -> pb.CloudFilter:
    f = pb.CloudFilter(
        min_range=_meters(min_range, "min_range"),
        max_range=_meters(max_range, "max_range", positive=True),
        voxel=_meters(voxel, "voxel"),
        self_filter=bool(self_filter),
        self_filter_padding=_meters(self_filter_padding, "self_filter_padding"),
    )
    if workspace is not None:
        box = np.asarray(workspace, dtype=float)
        if box.shape != (2, 3):
            raise ValueError(f"`workspace`: expected (min corner, max corner), shape (2, 3), got {box.shape}")
        f.workspace_min.CopyFrom(pb.Vec3(x=box[0, 0], y=box[0, 1], z=box[0, 2]))
        f.workspace_max.CopyFrom(pb.Vec3(x=box[1, 0], y=box[1, 1], z=box[1, 2]))
    if outliers is not None:
        try:
            neighbors, std_ratio = outliers
        except (TypeError, ValueError):
            raise ValueError(f"`outliers`: expected (neighbors, std_ratio), got {outliers!r}") from None
        f.outliers.CopyFrom(pb.OutlierFilter(neighbors=int(neighbors), std_ratio=float(std_ratio)))
    return f


class CloudCalls:
    """The point-cloud calls of :class:`~sublevel_client.Client` (a mixin: it relies on the
    client's ``_call``)."""

    def update_point_cloud(
        self,
        scene: str,
        name: str,
        points: Any = None,
        depth: Any = None,
        *,
        fx: Optional[float] = None,
        fy: Optional[float] = None,
        cx: Optional[float] = None,
        cy: Optional[float] = None,
        depth_scale: float = 0.001,
        sensor_pose: Any = None,
        noise_radius: float = 0.01,
        voxel: float = 0.02,
        min_range: float = 0.0,
        max_range: float = 10.0,
        workspace: Optional[Sequence[Sequence[float]]] = None,
        outliers: Optional[Tuple[int, float]] = None,
        self_filter: bool = False,
        self_filter_padding: float = 0.02,
        model: str = "points",
        body_degree: int = 4,
        body_tolerance: float = 0.05,
        body_min_points: int = 10,
        body_rescale_limit: float = 1.25,
    ) -> PointCloudUpdate:
        """Sets (or replaces) the point cloud ``name`` of ``scene`` from one sensor frame: the
        server filters it, keeps each point as a ball of ``noise_radius`` in the world frame, and
        swaps it in atomically (a check sees the old cloud or the new one, never a mix).

        Args:
            scene: the scene id.
            name: the cloud's name (1 to 256 bytes; not the name or id of an instance of the
                scene). A cloud of that name is replaced.
            points: an (N, 3) array of points in the sensor frame (meters; float32 or float64,
                sent as float32); NaN rows are holes (counted, not errors). N = 0 is an empty
                cloud.
            depth: or an (H, W) depth image, deprojected on the server through ``fx``, ``fy``,
                ``cx``, ``cy`` (pixels) in the camera's optical frame (z forward, x right, y
                down): uint16 pixels in units of ``depth_scale`` meters (default millimeters), or
                float pixels in meters; 0 (and NaN) is a hole.
            sensor_pose: the sensor frame in the world (a :class:`Pose`, 7-vector or 4x4 matrix);
                None: the points are in the world frame.
            noise_radius: the radius of every point's ball, meters (0 to 1).
            voxel: edge of the voxel grid, meters (each occupied voxel keeps the mean of its
                points); 0 turns it off.
            min_range, max_range: points nearer or farther from the sensor are dropped (meters).
            workspace: (min corner, max corner) of a world box outside which points are dropped.
            outliers: (neighbors, std_ratio): statistical outlier removal (PCL's); None: off.
            self_filter: drop the points whose ball comes within ``self_filter_padding`` meters
                of the scene's robot at the scene's joint positions (the arm in the sensor's
                view).
            model: how the checks see the cloud: ``"points"`` (every kept point a ball; exact
                against the filtered cloud) or ``"bodies"`` (the points' Euclidean clusters, each
                fitted by a convex sos body containing its points' balls, warm-started from this
                cloud's previous bodies: a body that still contains its cluster is kept).
            body_degree: degree 2d of the bodies, 2 or 4.
            body_tolerance: largest step within one cluster, meters.
            body_min_points: clusters with fewer points are outliers, dropped.
            body_rescale_limit: largest growth of a body by rescaling since its last fit (>= 1;
                1 never rescales).

        Returns a :class:`PointCloudUpdate` (scene version, filter counts, memory, server time,
        and for the bodies model what it did).
        Raises ValueError naming the argument for a malformed array or setting (nothing is sent),
        and SublevelError for the server's refusals: INVALID_ARGUMENT naming the field
        (``name``, ``filter.voxel``, ``depth.width``, …), NOT_FOUND for the scene,
        FAILED_PRECONDITION for ``self_filter`` in a scene without a robot, RESOURCE_EXHAUSTED
        past 16 clouds in the scene or the server's cloud memory (``--max-cloud-bytes``).
        """
        if (points is None) == (depth is None):
            raise ValueError("`points` / `depth`: give exactly one of them")
        radius = _meters(noise_radius, "noise_radius")
        req = pb.UpdatePointCloudRequest(scene_id=scene, name=name, noise_radius=radius)
        if points is not None:
            req.points.CopyFrom(_packed_points(points))
        else:
            req.depth.CopyFrom(_depth_image(depth, fx, fy, cx, cy, depth_scale))
        if sensor_pose is not None:
            req.sensor_pose.CopyFrom(_pose_pb(sensor_pose, "sensor_pose"))
        req.filter.CopyFrom(
            _cloud_filter(
                min_range=min_range,
                max_range=max_range,
                voxel=voxel,
                workspace=workspace,
                outliers=outliers,
                self_filter=self_filter,
                self_filter_padding=self_filter_padding,
            )
        )
        if model not in ("points", "bodies"):
            raise ValueError(f"`model`: 'points' or 'bodies', got {model!r}")
        if model == "bodies":
            if body_degree not in (2, 4):
                raise ValueError(f"`body_degree`: 2 or 4, got {body_degree!r}")
            req.model = pb.CLOUD_MODEL_BODIES
            req.bodies.CopyFrom(
                pb.CloudBodyOptions(
                    degree=int(body_degree),
                    tolerance=_meters(body_tolerance, "body_tolerance", positive=True),
                    min_points=int(body_min_points),
                    rescale_limit=float(body_rescale_limit),
                )
            )
        r = self._call("UpdatePointCloud", req)
        return PointCloudUpdate(
            scene_version=int(r.scene_version),
            counts=FilterCounts.from_proto(r.counts),
            memory_bytes=int(r.memory_bytes),
            seconds=float(r.seconds),
            bodies=CloudBodiesReport.from_proto(r.bodies) if r.HasField("bodies") else None,
        )

    def remove_point_cloud(self, scene: str, name: str) -> int:
        """Removes the point cloud ``name`` of ``scene`` (SublevelError NOT_FOUND when it has none
        of that name); returns the scene version the removal produced."""
        return int(self._call("RemovePointCloud", pb.RemovePointCloudRequest(scene_id=scene, name=name)).scene_version)
