"""The typed client: :class:`Client` (unary calls) and :class:`PlannerStream` (one QueryStream).

Units everywhere: meters for lengths, unit quaternions ``(w, x, y, z)`` for rotations; a pose maps
body-frame points to world points, ``x_world = R x_body + t``.
"""

from __future__ import annotations

import json
import math
import os
import queue
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, List, Mapping, Optional, Sequence, Tuple, Union

import grpc
import numpy as np

from ._pb.sublevel.v1 import sublevel_pb2 as pb
from ._pb.sublevel.v1 import sublevel_pb2_grpc as pb_grpc
from .errors import SublevelError
from .poses import Pose, as_pose
from .types import (
    Answer,
    AnswerColumns,
    BodySummary,
    ConfigurationColumns,
    DistanceAnswer,
    GrowthAnswer,
    ImportedInstance,
    ImportedScene,
    Instance,
    InstanceMotionColumns,
    MotionColumns,
    QueryResult,
    RobotInfo,
    Scene,
    SceneCheck,
    SceneRobot,
    SceneSummary,
    StateAnswers,
    UploadedBody,
    answer_from_proto,
)

__all__ = ["Client", "PlannerStream", "Query", "DEFAULT_ADDR"]

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


def _link_padding(link_padding: Optional[Mapping[str, float]]) -> dict:
    return {str(k): float(v) for k, v in (link_padding or {}).items()}


class Client:
    """A connection to a Sublevel server.

    >>> c = Client("127.0.0.1:50051")                          # doctest: +SKIP
    >>> scene = c.create_scene("table")                        # doctest: +SKIP
    >>> a = c.add_instance(scene, body_id, Pose(t=(0, 0, 0)))  # doctest: +SKIP

    Every call raises :class:`SublevelError` (code, message, field) when the server refuses it, and
    ValueError naming the argument when a pose or query is malformed before anything is sent.

    Args:
        addr: ``host:port`` of the server (insecure channel).
        timeout: deadline in seconds of each unary call (None: no deadline).
        channel: use this channel instead of opening one (``addr`` is then ignored).
        options: extra gRPC channel options.
    """

    def __init__(
        self,
        addr: str = DEFAULT_ADDR,
        *,
        timeout: Optional[float] = 60.0,
        channel: Optional[grpc.Channel] = None,
        options: Sequence[Tuple[str, Any]] = (),
    ):
        self.addr = addr
        self.timeout = timeout
        opts = [("grpc.max_receive_message_length", 256 << 20), ("grpc.max_send_message_length", 256 << 20)]
        opts += list(options)
        self._own_channel = channel is None
        self.channel = channel if channel is not None else grpc.insecure_channel(addr, options=opts)
        self.stub = pb_grpc.SublevelStub(self.channel)
        self._robots: dict = {}  # robot summaries by id (joint counts for the shape checks)

    # -- plumbing -----------------------------------------------------------------------------
    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Closes the channel (when this client opened it)."""
        if self._own_channel:
            self.channel.close()

    def wait_ready(self, timeout: float = 10.0) -> None:
        """Blocks until the channel is connected; raises SublevelError(UNAVAILABLE) after
        ``timeout`` seconds."""
        try:
            grpc.channel_ready_future(self.channel).result(timeout=timeout)
        except grpc.FutureTimeoutError:
            raise SublevelError(grpc.StatusCode.UNAVAILABLE, f"no server at {self.addr} after {timeout} s") from None

    def _call(self, method: str, request: Any, timeout: Optional[float] = None) -> Any:
        # Scale-out routing (deploy/SCALING.md): a proxy sends every call of a scene to the replica
        # that owns it by the `x-scene-id` header; servers ignore it.
        scene = getattr(request, "scene_id", "")
        metadata = ((SCENE_ID_HEADER, scene),) if scene else None
        try:
            return getattr(self.stub, method)(
                request, timeout=self.timeout if timeout is None else timeout, metadata=metadata
            )
        except grpc.RpcError as e:
            raise SublevelError.from_rpc_error(e) from None

    # -- bodies -------------------------------------------------------------------------------
    def upload(self, name: str, body: Any) -> UploadedBody:
        """Stores a body; like :meth:`upload_body` but returns the whole response (id, nonconvex,
        certified convexity margin)."""
        r = self._call("UploadBody", pb.UploadBodyRequest(name=name, body_json=_body_json(body)))
        return UploadedBody(
            body_id=r.body_id, nonconvex=r.nonconvex, convexity_margin=r.convexity_margin, nodes=r.nodes
        )

    def upload_body(self, name: str, body: Any) -> str:
        """Stores a body and returns its id.

        Args:
            name: a human-readable name (need not be unique).
            body: the JSON body file (``degree``, ``exponents``, ``coefficients``, ``center`` and
                ``scale`` in meters, optional ``report``) as JSON text, a path to such a file, or
                a dict (see :func:`sublevel_client.sphere_body`).
        """
        return self.upload(name, body).body_id

    def upload_primitive(
        self,
        kind: str,
        *,
        size: Optional[Sequence[float]] = None,
        radius: Optional[float] = None,
        height: Optional[float] = None,
        normal: Optional[Sequence[float]] = None,
        offset: Optional[float] = None,
        name: Optional[str] = None,
    ) -> str:
        """Stores an exact primitive (no fit) and returns its body id; it is used as any body is
        (instances, queries, scene checks), and answered exactly (docs/primitives.md).

        Args:
            kind: ``"box"`` (``size``: full side lengths x, y, z), ``"sphere"`` (``radius``),
                ``"cylinder"`` (``radius``, ``height``: full length along z), ``"capsule"``
                (``radius``, ``height``: the axis segment's length, 0 allowed) or ``"halfspace"``
                (``normal``, ``offset``: the set ``normal · u <= offset``). Meters, centered at the
                body frame's origin.
            name: a human-readable name (default: the kind).

        Only the dimensions of ``kind`` may be given; the server refuses a bad one naming it
        (``SublevelError.field == "primitive.size[1]"``), and ``kind`` unknown raises ValueError.

        >>> table = c.upload_primitive("box", size=(1.2, 0.8, 0.04))   # doctest: +SKIP
        >>> floor = c.upload_primitive("halfspace", normal=(0, 0, 1), offset=0.0)  # doctest: +SKIP
        """
        p = _primitive_pb(kind, size=size, radius=radius, height=height, normal=normal, offset=offset)
        req = pb.UploadBodyRequest(name=kind if name is None else name, primitive=p)
        return self._call("UploadBody", req).body_id

    def list_bodies(self) -> List[BodySummary]:
        """All stored bodies (summaries), ordered by id (every page of ListBodies)."""
        out, token = [], ""
        while True:
            r = self._call("ListBodies", pb.ListBodiesRequest(page_token=token))
            out += [BodySummary(b.body_id, b.name, b.degree, b.method, b.volume, b.primitive) for b in r.bodies]
            token = r.next_page_token
            if not token:
                return out

    def get_body_json(self, body_id: str) -> str:
        """A stored body as its JSON body file."""
        return self._call("GetBody", pb.GetBodyRequest(body_id=body_id)).body_json

    def delete_body(self, body_id: str) -> None:
        """Deletes a body (FAILED_PRECONDITION while an instance uses it)."""
        self._call("DeleteBody", pb.DeleteBodyRequest(body_id=body_id))

    # -- scenes -------------------------------------------------------------------------------
    def create_scene(self, name: str) -> str:
        """Creates an empty scene; returns its id."""
        return self._call("CreateScene", pb.CreateSceneRequest(name=name)).scene_id

    def get_scene(self, scene_id: str) -> Scene:
        """A scene with its instances and their poses, its robot (:class:`SceneRobot`, None when
        it has none) and its joint positions by name."""
        r = self._call("GetScene", pb.GetSceneRequest(scene_id=scene_id))
        return Scene(
            scene_id=r.scene_id,
            name=r.name,
            instances=[Instance.from_proto(i) for i in r.instances],
            robot=SceneRobot.from_proto(r.robot) if r.HasField("robot") else None,
            joint_positions={j.name: j.position for j in r.joint_positions},
        )

    def list_scenes(self) -> List[SceneSummary]:
        """All scenes (summaries), ordered by id (every page of ListScenes)."""
        out, token = [], ""
        while True:
            r = self._call("ListScenes", pb.ListScenesRequest(page_token=token))
            out += [SceneSummary(s.scene_id, s.name, s.num_instances) for s in r.scenes]
            token = r.next_page_token
            if not token:
                return out

    def find_scene(self, name: str) -> str:
        """The id of the first scene (by id) named ``name``; KeyError if none."""
        for s in self.list_scenes():
            if s.name == name:
                return s.scene_id
        raise KeyError(f"no scene named {name!r}")

    def import_scene(
        self,
        scene: Any,
        name: Optional[str] = None,
        *,
        skip_meshes: bool = False,
        mesh_tolerance: float = 0.0,
        wait: bool = False,
        progress: Any = None,
        timeout: Optional[float] = None,
    ) -> ImportedScene:
        """Imports a MoveIt planning scene (``moveit_msgs/PlanningScene``) as a new scene: each
        collision object's primitives (box, sphere, cylinder; a cone as its cylinder) and planes
        (the halfspace opposite the normal) become instances of exact primitive bodies at their
        composed poses; each mesh is fitted as a compound body containing it by a fit job of its
        own (``ImportedScene.meshes``), which adds the body's instance at the mesh's composed pose
        under the object's name when it ends.

        Args:
            scene: the scene as YAML or JSON — a path (``str`` or ``os.PathLike``; JSON when it
                ends in ``.json``), ``bytes``, or the text itself (JSON when it starts with ``{``).
            name: the new scene's name (default: the planning scene's ``name``, else
                ``"imported"``).
            skip_meshes: skip the meshes instead (``ImportedScene.skipped``, with their poses).
            mesh_tolerance: leaf-excess tolerance of the meshes' fits, meters; 0: 1 % of each
                mesh's bounding-box diagonal.
            wait: wait for the meshes' jobs, so the returned scene is complete: each
                :class:`ImportedMesh` then carries its job's state, body and message, and the
                meshes' instances are in ``instances`` (and ``.ids``).
            progress: with ``wait``, called with each ``FitJobUpdate`` of the meshes' jobs.
            timeout: with ``wait``, seconds to wait for each job (None: no limit).

        Returns the :class:`ImportedScene` (instance ids by name in ``.ids``, the allowed-collision
        matrix and joint positions). A bad scene raises SublevelError naming its field
        (``yaml.world.collision_objects[3].primitive_poses[0]``); with ``wait``, a mesh job that
        does not succeed raises SublevelError (ABORTED) with its error (the scene stays).
        """
        json_form = False
        if isinstance(scene, os.PathLike) or (isinstance(scene, str) and os.path.isfile(scene)):
            path = os.fspath(scene)
            with open(path, "rb") as f:
                data = f.read()
            json_form = path.lower().endswith(".json")
        elif isinstance(scene, (bytes, bytearray)):
            data = bytes(scene)
            json_form = data.lstrip().startswith(b"{")
        elif isinstance(scene, str):
            data = scene.encode("utf-8")
            json_form = scene.lstrip().startswith("{")
        else:
            raise ValueError(f"`scene`: expected a path, bytes or text, got {type(scene).__name__}")
        req = pb.ImportSceneRequest(
            name=name or "", skip_meshes=bool(skip_meshes), mesh_tolerance=float(mesh_tolerance)
        )
        if json_form:
            req.json = data
        else:
            req.yaml = data
        imported = ImportedScene.from_proto(self._call("ImportScene", req))
        if wait and imported.meshes:
            self._wait_meshes(imported, progress, timeout)
        return imported

    def _wait_meshes(self, imported: ImportedScene, progress: Any, timeout: Optional[float]) -> None:
        """Waits for each mesh job of ``imported``, records its outcome in its
        :class:`ImportedMesh` and adds the instances the jobs placed to ``imported.instances``."""
        for mesh in imported.meshes:
            last = self._wait_job(mesh.job_id, progress, timeout)
            mesh.state = pb.JobState.Name(last.state).removeprefix("JOB_STATE_")
            mesh.body_id, mesh.message, mesh.error = last.body_id, last.message, last.error
            if last.state != pb.JOB_STATE_SUCCEEDED:
                raise SublevelError(
                    grpc.StatusCode.ABORTED,
                    f"mesh {mesh.name!r} of scene {imported.scene_id}: fit job {mesh.job_id} did not succeed: {last.error}",
                )
        by_body = {i.body_id: i for i in self.get_scene(imported.scene_id).instances}
        for mesh in imported.meshes:
            placed = by_body.get(mesh.body_id)
            if placed is None:
                continue  # not added (the scene filled up): the job's message says why
            imported.instances.append(
                ImportedInstance(
                    name=mesh.name,
                    object_id=mesh.object_id,
                    shape_index=mesh.shape_index,
                    instance_id=placed.instance_id,
                    body_id=mesh.body_id,
                    kind="mesh",
                    pose=mesh.pose,
                    frame_id=mesh.frame_id,
                    note="a compound body fitted to the mesh (it contains the mesh)",
                )
            )

    def _wait_job(self, job_id: str, progress: Any = None, timeout: Optional[float] = None) -> Any:
        """Follows fit job ``job_id`` (``WatchFitJob``) until it ends, calling ``progress`` with
        each ``FitJobUpdate``; returns the terminal update. Raises SublevelError for the stream's
        errors and for a stream that ends without an update."""
        last = None
        try:
            for update in self.stub.WatchFitJob(pb.WatchFitJobRequest(job_id=job_id), timeout=timeout):
                last = update
                if progress is not None:
                    progress(update)
        except grpc.RpcError as e:
            raise SublevelError.from_rpc_error(e) from None
        if last is None:
            raise SublevelError(grpc.StatusCode.ABORTED, f"fit job {job_id}: no update")
        return last

    def delete_scene(self, scene_id: str) -> None:
        """Deletes a scene with its instances (the bodies stay)."""
        self._call("DeleteScene", pb.DeleteSceneRequest(scene_id=scene_id))

    def add_instance(self, scene: str, body: str, pose: Any = None) -> str:
        """Adds an instance of body ``body`` to scene ``scene`` under ``pose`` (a :class:`Pose`,
        a 7-vector ``[w, x, y, z, tx, ty, tz]`` or a 4x4 matrix; meters; None: identity).
        Returns the instance id."""
        req = pb.AddInstanceRequest(scene_id=scene, body_id=body, pose=_pose_pb(pose, "pose"))
        return self._call("AddInstance", req).instance_id

    def remove_instance(self, scene: str, instance: str) -> None:
        """Removes an instance (and its warm starts)."""
        self._call("RemoveInstance", pb.RemoveInstanceRequest(scene_id=scene, instance_id=instance))

    def set_poses(self, scene: str, poses: PosesLike) -> int:
        """Sets the stored poses of many instances at once (all or nothing).

        Args:
            poses: ``{instance_id: pose}`` (or ``(instance_id, pose)`` pairs), each pose a
                :class:`Pose`, a 7-vector or a 4x4 matrix (meters, unit quaternion w, x, y, z).
        Returns the number of instances updated.
        """
        req = pb.SetPosesRequest(scene_id=scene, poses=_instance_poses(poses, "poses"))
        return self._call("SetPoses", req).updated

    # -- robots -------------------------------------------------------------------------------
    def fit_robot(
        self,
        urdf: Union[str, "os.PathLike[str]"],
        *,
        srdf: Union[str, "os.PathLike[str]", None] = None,
        package_dirs: Sequence[Union[str, "os.PathLike[str]"]] = (),
        name: str = "",
        tolerance: float = 0.0,
        max_parts: int = 0,
        progress: Any = None,
        timeout: Optional[float] = None,
    ) -> RobotInfo:
        """Fits a robot on the server from its URDF (``StartRobotFitJob``) and waits for it, as
        ``sublevel robot fit`` does: URDF primitives stay exact, each link mesh becomes a compound
        sos-convex body containing it (cached by content on the server, so a re-fit is quick), the
        SRDF's disabled pairs become the allowed pairs.

        Args:
            urdf: the URDF file. Every mesh its collision elements name is read and sent:
                ``package://NAME/PATH`` from ``DIR/NAME/PATH`` for the first of ``package_dirs``
                that has it (as ROS and pinocchio resolve it), a relative path from the URDF's
                directory.
            srdf: the SRDF file, if any.
            name: the stored robot's name; empty: the URDF's robot name.
            tolerance: leaf-excess tolerance of each mesh's fit, meters; 0: 1 % of each mesh's
                bounding-box diagonal.
            max_parts: most leaves per link (2..64); 0: 32.
            progress: called with each ``FitJobUpdate`` (``fraction``, ``message``: one per mesh).
            timeout: seconds to wait for the job (None: no limit; the Panda takes minutes).

        Returns the stored robot's :class:`RobotInfo`. Raises FileNotFoundError naming a mesh the
        URDF names that no place holds, SublevelError for the server's refusals (INVALID_ARGUMENT
        naming the field) and for a job that fails or is cancelled (its error as the message).
        """
        import xml.etree.ElementTree as ET

        urdf_path = Path(urdf)
        text = urdf_path.read_text()
        meshes = {}
        for mesh in ET.fromstring(text).iter("mesh"):
            filename = mesh.get("filename", "")
            if not filename or filename in meshes:
                continue
            if filename.startswith("package://"):
                rest = filename[len("package://"):]
                places = [Path(d) / rest for d in package_dirs]
            else:
                places = [urdf_path.parent / filename]
            found = next((p for p in places if p.is_file()), None)
            if found is None:
                raise FileNotFoundError(f"mesh {filename!r} of the URDF: not found in {[str(p) for p in places]}")
            meshes[filename] = found.read_bytes()
        req = pb.StartRobotFitJobRequest(
            name=name,
            urdf=text,
            srdf=Path(srdf).read_text() if srdf is not None else "",
            meshes=meshes,
            tolerance=float(tolerance),
            max_parts=int(max_parts),
        )
        job_id = self._call("StartRobotFitJob", req).job_id
        last = self._wait_job(job_id, progress, timeout)
        if last.state != pb.JOB_STATE_SUCCEEDED or not last.robot_id:
            error = last.error
            raise SublevelError(grpc.StatusCode.ABORTED, f"robot fit job {job_id} did not succeed: {error}")
        return self.get_robot(last.robot_id)

    def upload_robot(self, robot_file: Union[str, "os.PathLike[str]", bytes], name: str = "") -> RobotInfo:
        """Stores a fitted robot: the ``sublevel.robot.v1`` file that ``sublevel robot fit ...
        --output robot.json`` writes (its URDF, allowed pairs and link bodies; nothing is fitted
        here).

        Args:
            robot_file: a path to the file (read as bytes), its bytes, or its JSON text.
            name: a human-readable name; empty: the URDF's robot name.

        Returns the stored robot's :class:`RobotInfo`. A malformed file raises SublevelError
        (INVALID_ARGUMENT) naming the file's field.
        """
        req = pb.UploadRobotRequest(name=name, robot_file=_robot_file(robot_file))
        info = RobotInfo.from_proto(self._call("UploadRobot", req).robot)
        self._robots[info.robot_id] = info
        return info

    def get_robot(self, robot_id: str) -> RobotInfo:
        """A stored robot's summary: joint names and limits, links, geometry and pair counts
        (SublevelError NOT_FOUND when there is none)."""
        info = RobotInfo.from_proto(self._call("GetRobot", pb.GetRobotRequest(robot_id=robot_id)).robot)
        self._robots[info.robot_id] = info
        return info

    def list_robots(self) -> List[RobotInfo]:
        """Every stored robot's summary, ordered by id."""
        return [RobotInfo.from_proto(r) for r in self._call("ListRobots", pb.ListRobotsRequest()).robots]

    def delete_robot(self, robot_id: str) -> None:
        """Deletes a stored robot (SublevelError NOT_FOUND when there is none)."""
        self._robots.pop(robot_id, None)
        self._call("DeleteRobot", pb.DeleteRobotRequest(robot_id=robot_id))

    def _joint_count(self, robot: str, joint_names: List[str]) -> Tuple[int, str]:
        """The number of values per configuration and where it comes from: the joints named, else
        every joint of the robot (its summary, fetched once per robot)."""
        if joint_names:
            return len(joint_names), f"{len(joint_names)} joint_names"
        info = self._robots.get(robot)
        if info is None:
            info = self.get_robot(robot)
        return info.dof, f"robot {robot} has {info.dof} joints"

    def _scene_robot_joints(self, scene: str) -> List[str]:
        """The joint names of the robot of ``scene``, in its order (one GetScene). SublevelError
        INVALID_ARGUMENT naming ``robot_id`` when the scene has no robot, as the server answers a
        check naming no robot there."""
        placed = self.get_scene(scene).robot
        if placed is None:
            raise SublevelError(
                grpc.StatusCode.INVALID_ARGUMENT,
                f"invalid argument `robot_id`: required: name a robot, or a scene holding one "
                f"(scene `{scene}` has none; see set_scene_robot)",
                "robot_id",
            )
        return placed.joint_names

    def _joints(
        self,
        robot: Optional[str],
        scene: str,
        joint_names: Optional[Sequence[str]],
        scene_joints: Optional[Callable[[str], List[str]]] = None,
    ) -> Tuple[str, List[str], int, str]:
        """The robot id to send ("" for the scene's robot), the joint names to send, the values per
        configuration and where that count comes from (for the shape errors).

        With no ``robot`` and no ``joint_names``, the joints are every joint of the scene's robot,
        in its order, sent by name (``scene_joints(scene)``, default one GetScene): a robot
        replaced in between then fails loudly on an unknown joint instead of reading the values
        with another robot's joints."""
        if robot is not None and not isinstance(robot, str):
            raise ValueError(f"`robot`: expected a robot id string or None, got {robot!r}")
        if not isinstance(scene, str):
            raise ValueError(f"`scene`: expected a scene id string, got {scene!r}")
        names = _joint_names(joint_names)
        if robot:
            n, what = self._joint_count(robot, names)
            return robot, names, n, what
        if not scene:
            raise ValueError("`robot`: required without `scene`: name a robot, or a scene holding one")
        if names:
            return "", names, len(names), f"{len(names)} joint_names"
        names = (scene_joints or self._scene_robot_joints)(scene)
        return "", list(names), len(names), f"the robot of scene {scene} has {len(names)} joints"

    def _configurations_request(
        self,
        robot: Optional[str],
        q: Any,
        *,
        scene: str = "",
        joint_names: Optional[Sequence[str]] = None,
        base: Any = None,
        padding: float = 0.0,
        distance: bool = False,
        self_collision: bool = True,
        gradient: bool = False,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
        stop_at_first_collision: bool = False,
        scene_joints: Optional[Callable[[str], List[str]]] = None,
    ) -> pb.CheckConfigurationsRequest:
        """The ``CheckConfigurationsRequest`` of :meth:`check_configurations` (same arguments),
        validated here; also ``QueryRequest.robot_states`` on a stream."""
        robot_id, names, n, what = self._joints(robot, scene, joint_names, scene_joints)
        values = _configurations(q, n, "q", what)
        req = pb.CheckConfigurationsRequest(
            robot_id=robot_id,
            scene_id=scene,
            configurations=_configuration_columns(values, names),
            padding=float(padding),
            distance=bool(distance or gradient),
            skip_self=not self_collision,
            gradient=bool(gradient),
            attached=_attached_pb(attached),
            link_padding=_link_padding(link_padding),
            stop_at_first_collision=bool(stop_at_first_collision),
        )
        if base is not None:
            req.base.CopyFrom(_pose_pb(base, "base"))
        return req

    def _motions_request(
        self,
        robot: Optional[str],
        q0: Any,
        q1: Any,
        *,
        scene: str = "",
        joint_names: Optional[Sequence[str]] = None,
        base: Any = None,
        padding: float = 0.0,
        tolerance: float = 1e-3,
        max_steps: int = 0,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
        scene_joints: Optional[Callable[[str], List[str]]] = None,
    ) -> pb.CheckMotionsRequest:
        """The ``CheckMotionsRequest`` of :meth:`check_motions` (same arguments), validated here;
        also ``QueryRequest.robot_motions`` on a stream."""
        robot_id, names, n, what = self._joints(robot, scene, joint_names, scene_joints)
        start = _configurations(q0, n, "q0", what)
        end = _configurations(q1, n, "q1", what)
        if start.shape != end.shape:
            raise ValueError(f"`q1`: {end.shape[0]} configurations, `q0` has {start.shape[0]}")
        if not (float(tolerance) > 0.0) or not math.isfinite(float(tolerance)):
            raise ValueError(f"`tolerance`: expected a positive number of meters, got {tolerance!r}")
        if int(max_steps) < 0:
            raise ValueError(f"`max_steps`: expected >= 0, got {max_steps!r}")
        req = pb.CheckMotionsRequest(
            robot_id=robot_id,
            scene_id=scene,
            start=_configuration_columns(start, names),
            end=_configuration_columns(end, names),
            padding=float(padding),
            tolerance=float(tolerance),
            max_steps=int(max_steps),
            attached=_attached_pb(attached),
            link_padding=_link_padding(link_padding),
        )
        if base is not None:
            req.base.CopyFrom(_pose_pb(base, "base"))
        return req

    def check_configurations(
        self,
        robot: Optional[str],
        q: Any,
        *,
        scene: str = "",
        joint_names: Optional[Sequence[str]] = None,
        base: Any = None,
        padding: float = 0.0,
        distance: bool = False,
        self_collision: bool = True,
        gradient: bool = False,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
        stop_at_first_collision: bool = False,
    ) -> ConfigurationColumns:
        """Checks joint configurations of a stored robot among a scene's primitives, in columns.

        No configuration the collision meshes call colliding is answered free, and none they call
        free is answered colliding; the distance is the meshes' (docs/robots.md).

        Args:
            robot: the robot's id (:meth:`upload_robot`); None (or ""): the robot of ``scene``
                (:meth:`set_scene_robot`) with its base unless ``base`` is given, its attached
                objects plus ``attached``, and its link padding overridden link by link by
                ``link_padding``.
            q: the configurations, array-like of shape (N, n), or (n,) for one: radians for
                revolute and continuous joints, meters for prismatic ones.
            scene: the world: a scene of primitive instances (e.g. :meth:`import_scene`'s, whose
                allowed-collision matrix then applies); empty: no world (self-collision only).
            joint_names: the n joints of ``q``'s columns, each once; None: every joint of the
                robot in :attr:`RobotInfo.joint_names` order (with ``robot`` None: of the scene's
                robot, looked up with one GetScene per call; name the joints to skip it). Joints
                not named take the scene's joint positions, else 0.
            base: the pose of the robot's root link in the scene (a :class:`Pose`, a 7-vector
                ``[w, x, y, z, tx, ty, tz]`` or a 4x4 matrix; meters); None: the identity (the
                scene robot's base with ``robot`` None).
            padding: meters (>= 0) around every robot geometry: a pair closer than it collides.
            distance: also compute the minimum robot–world distance, its pair and witnesses
                (else the world pairs stop at the first collision).
            self_collision: check the robot's self pairs (False skips them).
            gradient: also compute the distance's joint-space gradient (implies ``distance``).
            attached: objects grasped for this call, each a dict ``{"link", "name", "kind",
                "size" / "radius" / "height", "origin"}`` (an exact primitive at ``origin`` in the
                link's frame, meters): it moves with the link and is checked like it.
            link_padding: meters (>= 0) per link name, on top of ``padding``, as MoveIt's link
                padding: a world pair collides within ``padding + p(link)``, a self pair within
                ``padding + p(a) + p(b)``; distances stay unpadded.
            stop_at_first_collision: check the rows in order and stop at the first that
                collides: the answer then has that many rows, the last one colliding (a sampled
                motion's states in van der Corput order find a collision in a few checks).

        Returns :class:`ConfigurationColumns` (numpy columns of N rows, fewer with
        ``stop_at_first_collision``). Raises ValueError naming
        the argument when ``q``, ``joint_names`` or ``base`` is malformed, or ``robot`` is None
        without a ``scene`` (nothing is sent), and SublevelError for the server's refusals:
        NOT_FOUND for an unknown robot or scene, INVALID_ARGUMENT naming the field
        (``configurations.joint_names[2]`` for an unknown joint, ``robot_id`` for ``robot`` None
        in a scene without a robot), FAILED_PRECONDITION for a scene holding a fitted body.
        """
        req = self._configurations_request(
            robot, q, scene=scene, joint_names=joint_names, base=base, padding=padding, distance=distance,
            self_collision=self_collision, gradient=gradient, attached=attached, link_padding=link_padding,
            stop_at_first_collision=stop_at_first_collision,
        )
        return ConfigurationColumns.from_proto(self._call("CheckConfigurations", req), gradient=bool(gradient))

    def check_motions(
        self,
        robot: Optional[str],
        q0: Any,
        q1: Any,
        *,
        scene: str = "",
        joint_names: Optional[Sequence[str]] = None,
        base: Any = None,
        padding: float = 0.0,
        tolerance: float = 1e-3,
        max_steps: int = 0,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
    ) -> MotionColumns:
        """Checks straight joint-space motions ``q0[m] -> q1[m]`` (continuous joints the shorter
        way) by conservative advancement: each is proven free, or answered with its first contact
        parameter t* (within ``tolerance``), the configuration and the pair there. No sampling
        resolution to choose.

        Args:
            robot, scene, joint_names, base, padding, attached, link_padding: as in
                :meth:`check_configurations` (``robot`` None: the scene's robot).
            q0, q1: start and end configurations, array-like of the same shape, (M, n) or (n,)
                for one motion (radians, meters).
            tolerance: meters (> 0): a distance bound at or below ``padding + tolerance`` is a
                contact.
            max_steps: most advancement steps per motion before it is answered undecided
                (``decided`` false); 0: the server's default (100 000).

        Returns :class:`MotionColumns` (numpy columns of M rows). Raises ValueError naming the
        argument when ``q0``, ``q1``, ``joint_names``, ``base`` or ``tolerance`` is malformed
        (nothing is sent), and SublevelError for the server's refusals, as
        :meth:`check_configurations`.
        """
        req = self._motions_request(
            robot, q0, q1, scene=scene, joint_names=joint_names, base=base, padding=padding, tolerance=tolerance,
            max_steps=max_steps, attached=attached, link_padding=link_padding,
        )
        return MotionColumns.from_proto(self._call("CheckMotions", req))

    # -- robots in scenes ---------------------------------------------------------------------
    def set_scene_robot(
        self,
        scene: str,
        robot: str,
        base: Any = None,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
        joint_positions: Optional[Mapping[str, float]] = None,
    ) -> SceneRobot:
        """Places a stored robot in a scene, replacing the scene's robot (a scene holds at most
        one, as a MoveIt planning scene does). It is stored with the scene: :meth:`check_scene`
        then checks it at the scene's joint positions, and :meth:`check_configurations` /
        :meth:`check_motions` (and the stream's) with ``robot=None`` check it.

        Args:
            robot: the stored robot's id (:meth:`upload_robot`).
            base: the pose of its root link in the scene (a :class:`Pose`, a 7-vector or a 4x4
                matrix; meters); None: the identity.
            attached: objects attached to its links, dicts as :meth:`check_configurations` takes
                (names unique; no halfspace).
            link_padding: meters (>= 0) per link name.
            joint_positions: ``{joint name: value}`` (radians or meters) to set; None or empty:
                the scene's joint positions stay as they are.

        Returns the scene's :class:`SceneRobot` as it now is. All or nothing: ValueError naming
        the argument when one is malformed (nothing is sent), SublevelError NOT_FOUND for an
        unknown robot or scene, INVALID_ARGUMENT naming the field (``joint_positions.joint_names[0]``,
        ``attached[1].link``, ``link_padding[hand]``) and nothing changes.
        """
        req = pb.SetSceneRobotRequest(
            scene_id=scene,
            robot_id=robot,
            attached=_attached_pb(attached),
            link_padding=_link_padding(link_padding),
        )
        if base is not None:
            req.base.CopyFrom(_pose_pb(base, "base"))
        if joint_positions:
            req.joint_positions.CopyFrom(_joint_positions(joint_positions, "joint_positions"))
        return SceneRobot.from_proto(self._call("SetSceneRobot", req).robot)

    def clear_scene_robot(self, scene: str) -> bool:
        """Removes the robot of a scene; returns whether it had one. The scene's joint positions
        stay."""
        return self._call("ClearSceneRobot", pb.ClearSceneRobotRequest(scene_id=scene)).removed

    def set_joint_positions(self, scene: str, positions: Mapping[str, float]) -> SceneRobot:
        """Sets joint positions of the scene's robot, ``{joint name: value}`` (radians or
        meters); joints not named keep theirs.

        Returns the scene's :class:`SceneRobot` as it now is. All or nothing: ValueError naming
        ``positions[joint]`` for a value that is not a finite number (nothing is sent);
        SublevelError INVALID_ARGUMENT naming ``joint_positions.joint_names[k]`` for an unknown,
        fixed, mimic or repeated joint, FAILED_PRECONDITION when the scene has no robot, and
        nothing changes.
        """
        req = pb.SetJointPositionsRequest(scene_id=scene, joint_positions=_joint_positions(positions, "positions"))
        return SceneRobot.from_proto(self._call("SetJointPositions", req).robot)

    def attach_object(
        self,
        scene: str,
        link: str,
        name: str,
        kind: str,
        *,
        size: Optional[Sequence[float]] = None,
        radius: Optional[float] = None,
        height: Optional[float] = None,
        origin: Any = None,
    ) -> SceneRobot:
        """Attaches an exact primitive to a link of the scene's robot (a grasped object): it
        moves with the link and is checked like it; an attached object of the same ``name`` is
        replaced. The arguments are the keys of the dicts :meth:`check_configurations` takes for
        ``attached`` (so ``attach_object(scene, **robot.attached[k])`` re-attaches one).

        Args:
            link: the robot link.
            name: the object's name (required; ``robot_geometry`` in answers).
            kind, size, radius, height: the primitive, as :meth:`upload_primitive` (meters; no
                halfspace).
            origin: its pose in the link's frame (a :class:`Pose`, a 7-vector or a 4x4 matrix);
                None: the identity.

        Returns the scene's :class:`SceneRobot` as it now is. ValueError for an unknown ``kind``,
        an empty ``name`` or a malformed ``origin``; SublevelError INVALID_ARGUMENT naming the
        field (``attached.link``), FAILED_PRECONDITION when the scene has no robot.
        """
        if not isinstance(name, str) or not name:
            raise ValueError(f"`name`: required (a non-empty string), got {name!r}")
        obj = {"link": link, "name": name, "kind": kind, "size": size, "radius": radius, "height": height,
               "origin": origin}
        req = pb.AttachObjectRequest(scene_id=scene, attached=_attached_one(obj, "attached"))
        return SceneRobot.from_proto(self._call("AttachObject", req).robot)

    def detach_object(self, scene: str, name: str) -> SceneRobot:
        """Detaches the object ``name`` from the scene's robot; returns the :class:`SceneRobot`
        as it now is (SublevelError NOT_FOUND when it has no object of that name)."""
        req = pb.DetachObjectRequest(scene_id=scene, name=name)
        return SceneRobot.from_proto(self._call("DetachObject", req).robot)

    def check_instance_motions(
        self,
        scene: str,
        instance_ids: Union[str, Sequence[str]],
        start_poses: Any,
        end_poses: Any,
        *,
        padding: float = 0.0,
        tolerance: float = 1e-3,
        max_steps: int = 0,
    ) -> InstanceMotionColumns:
        """Checks rigid-body motions of scene instances by conservative advancement: motion m
        moves ``instance_ids[m]`` from ``start_poses[m]`` to ``end_poses[m]`` (translation along the
        segment, rotation along the shorter arc, both at constant speed) while every other
        instance stays at its stored pose. Each is proven free, or answered with its first contact
        parameter t* (within ``tolerance``), the pose there and the instance it touches. No
        sampling resolution to choose.

        Args:
            scene: the scene id; its instances at their stored poses are the obstacles.
            instance_ids: the moving instance of each motion (M ids; one id for one motion).
            start_poses, end_poses: array-like of shape (M, 7) (or (7,) for one motion): per
                motion the unit quaternion w, x, y, z, then the translation x, y, z in meters.
            padding: meters (>= 0) around the moving instance: it is in contact within this
                distance.
            tolerance: meters (> 0): a certified distance bound at or below ``padding +
                tolerance`` is a contact.
            max_steps: most advancement steps per motion before it is answered undecided
                (``decided`` false); 0: the server's default (100 000).

        Returns :class:`InstanceMotionColumns` (numpy columns of M rows). Raises ValueError
        naming the argument when ``instance_ids``, a pose array, ``padding``, ``tolerance`` or
        ``max_steps`` is malformed (nothing is sent), and SublevelError for the server's
        refusals (INVALID_ARGUMENT naming the field, e.g. a non-unit quaternion at
        ``start_poses[7m]`` or a halfspace at ``instance_ids[m]``; NOT_FOUND for an unknown scene or
        instance).
        """
        ids = [instance_ids] if isinstance(instance_ids, str) else list(instance_ids)
        if not ids or not all(isinstance(i, str) and i for i in ids):
            raise ValueError(f"`instance_ids`: expected one or more instance id strings, got {instance_ids!r}")
        start = _motion_poses(start_poses, len(ids), "start_poses")
        end = _motion_poses(end_poses, len(ids), "end_poses")
        if not (float(padding) >= 0.0) or not math.isfinite(float(padding)):
            raise ValueError(f"`padding`: expected a non-negative number of meters, got {padding!r}")
        if not (float(tolerance) > 0.0) or not math.isfinite(float(tolerance)):
            raise ValueError(f"`tolerance`: expected a positive number of meters, got {tolerance!r}")
        if int(max_steps) < 0:
            raise ValueError(f"`max_steps`: expected >= 0, got {max_steps!r}")
        req = pb.CheckInstanceMotionsRequest(
            scene_id=scene,
            instance_ids=ids,
            start_poses=start.ravel().tolist(),
            end_poses=end.ravel().tolist(),
            padding=float(padding),
            tolerance=float(tolerance),
            max_steps=int(max_steps),
        )
        return InstanceMotionColumns.from_proto(self._call("CheckInstanceMotions", req))

    # -- queries ------------------------------------------------------------------------------
    def distance(
        self,
        scene: str,
        a: str,
        b: str,
        certify: bool = False,
        with_gradient: bool = False,
        signed: bool = False,
        tolerance: float = 0.0,
    ) -> DistanceAnswer:
        """Euclidean distance (meters) between instances ``a`` and ``b`` at their stored poses, with
        witness points (world frame, meters), the normal from A to B, solver diagnostics, and
        (``with_gradient``) the gradients as (6,) twists; ``certify`` also solves the SDP;
        ``signed`` also returns the signed distance (minus the penetration depth when the bodies
        overlap) with the penetration normal. Pairs with a compound body: ``tolerance`` (meters,
        >= 0) stops the branch and bound once its bounds are that close (``answer.tree``)."""
        req = pb.DistanceRequest(
            scene_id=scene,
            instance_a=a,
            instance_b=b,
            certify=certify,
            with_gradient=with_gradient,
            signed=signed,
            tolerance=tolerance,
        )
        return DistanceAnswer.from_proto(self._call("Distance", req).answer)

    def growth(self, scene: str, p1: str, p2: str, certify: bool = False, with_gradient: bool = False) -> GrowthAnswer:
        """Growth measure d(p1 || p2) = min p1(x) s.t. p2(x) <= 1 (dimensionless; <= 1 iff the
        instances overlap) with its minimizer (world frame, meters)."""
        req = pb.GrowthRequest(scene_id=scene, instance_1=p1, instance_2=p2, certify=certify, with_gradient=with_gradient)
        return GrowthAnswer.from_proto(self._call("Growth", req).answer)

    def batch(self, scene: str, queries: Iterable[Any]) -> List[Answer]:
        """Many DISTANCE / GROWTH queries (:class:`Query` or ``(kind, first, second)`` tuples) at
        the stored poses in one call; answers in order."""
        pairs = []
        for k, q in enumerate(queries):
            q = as_query(q, f"queries[{k}]")
            if q.kind == "collide":
                raise ValueError(f"`queries[{k}].kind`: BatchQuery answers distance and growth only; use query()")
            pairs.append(
                pb.QueryPair(
                    kind=_KINDS[q.kind],
                    first=q.first,
                    second=q.second,
                    certify=q.certify,
                    with_gradient=q.with_gradient,
                    signed=q.signed,
                )
            )
        r = self._call("BatchQuery", pb.BatchQueryRequest(scene_id=scene, pairs=pairs))
        return [answer_from_proto(a) for a in r.answers]

    def batch_columns(
        self,
        scene: str,
        kind: str,
        first: Sequence[str],
        second: Sequence[str],
        margin: float = 0.0,
        cold: bool = False,
    ) -> AnswerColumns:
        """Pairs ``(first[k], second[k])`` of one ``kind`` (``"distance"``, ``"growth"`` or
        ``"collide"`` with ``margin`` meters) at the stored poses, in columns both ways: numpy
        arrays back (:class:`AnswerColumns`), no message per pair. The fast form for thousands of
        pairs. ``cold``: no warm start read or kept; distance / collide pairs of the same two bodies
        are then solved four per SIMD pass on the server (unrelated poses, e.g. sampled states)."""
        req = pb.BatchQueryRequest(scene_id=scene, columns=_pair_columns(kind, first, second, margin, cold))
        return AnswerColumns.from_proto(self._call("BatchQuery", req).columns)

    def query(
        self,
        scene: str,
        poses: PosesLike = None,
        queries: Iterable[Any] = (),
        states: Optional[Iterable[PosesLike]] = None,
    ) -> QueryResult:
        """A planner request on a private view of the scene (stored poses, then ``poses``; nothing
        is written, answers are cold).

        Args:
            poses: pose overrides ``{instance_id: pose}`` for this request only.
            queries: :class:`Query` objects or ``(kind, first, second[, margin])`` tuples.
            states: candidate states, each ``{instance_id: pose}``; when given, every query is
                answered once per state (``result.states``), else once (``result.answers``).
        """
        req = pb.QueryRequest(scene_id=scene, poses=_instance_poses(poses, "poses"), queries=_planner_queries(queries), states=_states(states))
        return QueryResult.from_proto(self._call("Query", req))

    def query_state_columns(self, scene: str, *args: Any, **kwargs: Any) -> AnswerColumns:
        """:meth:`PlannerStream.check_state_columns` (same arguments after ``scene``) as one unary
        Query on a private view of the scene (stored poses, then ``poses``): S × P rows, row
        s·P + k is pair k in state s."""
        req = _state_columns_query(scene, *args, **kwargs)
        return QueryResult.from_proto(self._call("Query", req)).columns

    def check_scene(
        self,
        scene: str,
        margin: float = 0.0,
        instances: Optional[Iterable[str]] = None,
        poses: PosesLike = None,
    ) -> SceneCheck:
        """Every pair of the scene that overlaps or lies within ``margin`` meters (or only pairs
        involving ``instances``), with distances and witnesses; ``poses`` override stored poses
        for this check only."""
        req = pb.CheckSceneRequest(
            scene_id=scene, margin=float(margin), instance_ids=list(instances or []), poses=_instance_poses(poses, "poses")
        )
        return SceneCheck.from_proto(self._call("CheckScene", req))

    def stream(self, scene: str, timeout: Optional[float] = None) -> "PlannerStream":
        """Opens a QueryStream on ``scene`` for a planner loop (see :class:`PlannerStream`)."""
        return PlannerStream(self, scene, timeout=timeout)


_CLOSE = object()


class PlannerStream:
    """One bidirectional QueryStream kept open: one request per call, answers in order.

    The stream keeps its own view of the scene: poses sent with a request stay in the stream's
    view for later requests (they are never written to the store nor seen by other streams), and
    warm starts are kept per stream and ordered pair, so consecutive nearby states solve fast.

    >>> with client.stream(scene) as s:                                        # doctest: +SKIP
    ...     answers = s.check(poses={robot: pose}, queries=[Query.collide(robot, wall, 0.05)])

    Joint configurations and motions of a robot (the scene's, by default) are checked against
    the stream's view too (:meth:`check_configurations`, :meth:`check_motions`).

    Thread-safe: calls from several threads are serialized (one request in flight). A request the
    server refuses ends the stream on the server side: the call raises :class:`SublevelError` and
    every later call raises it again; open a new stream.
    """

    def __init__(self, client: Client, scene: str, timeout: Optional[float] = None):
        self.scene = scene
        self._client = client
        self._scene_joints: Optional[List[str]] = None  # the scene robot's joints, looked up once
        self._requests: "queue.Queue[Any]" = queue.Queue()
        self._lock = threading.Lock()
        self._next_id = 1
        self._error: Optional[BaseException] = None
        self._closed = False
        try:
            self._responses = client.stub.QueryStream(
                self._request_iterator(), timeout=timeout, metadata=((SCENE_ID_HEADER, scene),)
            )
        except grpc.RpcError as e:  # pragma: no cover (the call starts lazily)
            raise SublevelError.from_rpc_error(e) from None

    def _request_iterator(self) -> Iterator[pb.QueryRequest]:
        while True:
            r = self._requests.get()
            if r is _CLOSE:
                return
            yield r

    def __enter__(self) -> "PlannerStream":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Half-closes the stream and waits for the server to end it."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._requests.put(_CLOSE)
            if self._error is None:
                try:
                    for _ in self._responses:
                        pass
                except grpc.RpcError:
                    pass
            else:
                self._responses.cancel()

    def request(
        self,
        poses: PosesLike = None,
        queries: Iterable[Any] = (),
        states: Optional[Iterable[PosesLike]] = None,
    ) -> QueryResult:
        """Sends one request (pose updates of the stream's view, queries, optional candidate
        states) and returns the whole response (answers, states, server seconds)."""
        req = pb.QueryRequest(
            scene_id=self.scene,
            poses=_instance_poses(poses, "poses"),
            queries=_planner_queries(queries),
            states=_states(states),
        )
        return self._send(req)

    def _send(self, req: pb.QueryRequest) -> QueryResult:
        return QueryResult.from_proto(self._exchange(req))

    def _exchange(self, req: pb.QueryRequest) -> pb.QueryResponse:
        """Sends one request and returns its response message (in order; see the class)."""
        with self._lock:
            if self._error is not None:
                raise self._error
            if self._closed:
                raise RuntimeError("the stream is closed")
            req.request_id = self._next_id
            self._next_id += 1
            self._requests.put(req)
            try:
                resp = next(self._responses)
            except grpc.RpcError as e:
                self._error = SublevelError.from_rpc_error(e)
                raise self._error from None
            except StopIteration:
                self._error = SublevelError(grpc.StatusCode.UNAVAILABLE, "the server ended the stream")
                raise self._error from None
        if resp.request_id != req.request_id:
            raise RuntimeError(f"stream out of order: sent request {req.request_id}, got {resp.request_id}")
        return resp

    def _scene_robot_joints(self, scene: str) -> List[str]:
        """The scene robot's joint names, looked up (one unary GetScene) at the stream's first
        check that needs them and kept for the stream's life."""
        if self._scene_joints is None:
            self._scene_joints = self._client._scene_robot_joints(scene)
        return self._scene_joints

    def check_configurations(
        self,
        q: Any,
        joint_names: Optional[Sequence[str]] = None,
        distance: bool = False,
        padding: float = 0.0,
        *,
        robot: Optional[str] = None,
        base: Any = None,
        self_collision: bool = True,
        gradient: bool = False,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
        stop_at_first_collision: bool = False,
        poses: PosesLike = None,
    ) -> ConfigurationColumns:
        """Checks joint configurations against the stream's view of the scene (its poses, after
        ``poses`` ``{instance_id: pose}`` are applied to it and kept, as in :meth:`check`): one
        request with ``QueryRequest.robot_states``. The arguments and the answer are those of
        :meth:`Client.check_configurations`, the world being the stream's scene; ``robot`` None
        (the default) is the scene's robot.

        With ``robot`` and ``joint_names`` None, the scene robot's joints are looked up once per
        stream (one unary GetScene at the first such call) and sent by name: a robot replaced
        during the stream is then refused on an unknown joint rather than read with other joints.

        Raises ValueError as :meth:`Client.check_configurations` (nothing is sent, the stream
        stays open), and SublevelError for the server's refusals with the field prefixed
        (``robot_states.configurations.joint_names[0]``); a refusal ends the stream.
        """
        req = self._client._configurations_request(
            robot, q, scene=self.scene, joint_names=joint_names, base=base, padding=padding, distance=distance,
            self_collision=self_collision, gradient=gradient, attached=attached, link_padding=link_padding,
            stop_at_first_collision=stop_at_first_collision, scene_joints=self._scene_robot_joints,
        )
        query = pb.QueryRequest(scene_id=self.scene, poses=_instance_poses(poses, "poses"), robot_states=req)
        return ConfigurationColumns.from_proto(self._exchange(query).robot_states, gradient=bool(gradient))

    def check_motions(
        self,
        q0: Any,
        q1: Any,
        joint_names: Optional[Sequence[str]] = None,
        padding: float = 0.0,
        tolerance: float = 1e-3,
        *,
        robot: Optional[str] = None,
        base: Any = None,
        max_steps: int = 0,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
        poses: PosesLike = None,
    ) -> MotionColumns:
        """Certifies joint-space motions ``q0[m] -> q1[m]`` against the stream's view of the scene
        (after ``poses`` are applied to it and kept): one request with
        ``QueryRequest.robot_motions``. The arguments and the answer are those of
        :meth:`Client.check_motions`; ``robot``, ``joint_names`` and errors as in
        :meth:`check_configurations` (fields prefixed ``robot_motions.``).
        """
        req = self._client._motions_request(
            robot, q0, q1, scene=self.scene, joint_names=joint_names, base=base, padding=padding,
            tolerance=tolerance, max_steps=max_steps, attached=attached, link_padding=link_padding,
            scene_joints=self._scene_robot_joints,
        )
        query = pb.QueryRequest(scene_id=self.scene, poses=_instance_poses(poses, "poses"), robot_motions=req)
        return MotionColumns.from_proto(self._exchange(query).robot_motions)

    def check_columns(
        self,
        kind: str,
        first: Sequence[str],
        second: Sequence[str],
        margin: float = 0.0,
        poses: PosesLike = None,
        states: Optional[Iterable[PosesLike]] = None,
        cold: bool = False,
    ) -> Union[AnswerColumns, List[AnswerColumns]]:
        """Like :meth:`check` (or, with ``states``, :meth:`check_states`) for pairs of one kind in
        columns: returns :class:`AnswerColumns` (one per state with ``states``). ``cold``: as
        :meth:`Client.batch_columns` (across ``states``, each pair's states are solved four per
        SIMD pass)."""
        cols = _pair_columns(kind, first, second, margin, cold)
        req = pb.QueryRequest(
            scene_id=self.scene, poses=_instance_poses(poses, "poses"), columns=cols, states=_states(states)
        )
        r = self._send(req)
        if states is not None:
            return [s.columns for s in r.states]
        return r.columns

    def check_state_columns(
        self,
        kind: str,
        first: Sequence[str],
        second: Sequence[str],
        instance_ids: Sequence[str],
        state_poses: Any,
        margin: float = 0.0,
        poses: PosesLike = None,
        cold: bool = False,
    ) -> AnswerColumns:
        """Candidate states in columns both ways (``QueryRequest.state_columns``): the pairs
        ``(first[k], second[k])`` of one ``kind`` answered in every state, where state s poses the
        instances ``instance_ids`` at ``state_poses[s]`` (an array of shape (S, n, 7): per instance,
        the unit quaternion w, x, y, z and the translation x, y, z in meters) on top of the view.
        Returns one :class:`AnswerColumns` of S × P rows, state-major: row s·P + k is pair k in
        state s (``cols.value.reshape(S, P)``). No message per state or pose either way: the fast
        form for a sampling planner's batch of states. ``cold``: as :meth:`check_columns`."""
        req = _state_columns_query(self.scene, kind, first, second, instance_ids, state_poses, margin, poses, cold)
        return self._send(req).columns

    def check(self, poses: PosesLike = None, queries: Iterable[Any] = ()) -> List[Answer]:
        """Applies ``poses`` ``{instance_id: pose}`` to the stream's view, then answers
        ``queries`` in order (one answer per query)."""
        return self.request(poses=poses, queries=queries).answers

    def check_states(
        self, states: Iterable[PosesLike], queries: Iterable[Any] = (), poses: PosesLike = None
    ) -> List[StateAnswers]:
        """Answers ``queries`` once per candidate state (each state ``{instance_id: pose}``
        applied on top of the view and dropped afterwards) in one request; one
        :class:`StateAnswers` per state, in order (``.any_collision`` per state)."""
        states = list(states)
        if not states:
            return []
        return self.request(poses=poses, queries=queries, states=states).states


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
