"""The typed client: :class:`Client` (unary calls) and :class:`PlannerStream` (one QueryStream).

Units everywhere: meters for lengths, unit quaternions ``(w, x, y, z)`` for rotations; a pose maps
body-frame points to world points, ``x_world = R x_body + t``.
"""

from __future__ import annotations

import math
import os
from typing import Any, Iterable, List, Optional, Sequence, Tuple, Union

import grpc

from ._pb.sublevel.v1 import sublevel_pb2 as pb
from ._pb.sublevel.v1 import sublevel_pb2_grpc as pb_grpc
from .errors import SublevelError
from .types import (
    Answer,
    AnswerColumns,
    BodySummary,
    DistanceAnswer,
    GrowthAnswer,
    ImportedInstance,
    ImportedScene,
    Instance,
    InstanceMotionColumns,
    QueryResult,
    Scene,
    SceneCheck,
    SceneRobot,
    SceneSummary,
    UploadedBody,
    answer_from_proto,
)
from ._requests import (
    DEFAULT_ADDR,
    PosesLike,
    Query,
    SCENE_ID_HEADER,
    _KINDS,
    _body_json,
    _instance_poses,
    _motion_poses,
    _pair_columns,
    _planner_queries,
    _pose_pb,
    _primitive_pb,
    _state_columns_query,
    _states,
    as_query,
)
from .clouds import CloudCalls, PointCloudInfo
from .plans import PlanCalls
from .robots import RobotCalls
from .stream import PlannerStream

__all__ = ["Client", "PlannerStream", "Query", "DEFAULT_ADDR"]


class Client(RobotCalls, PlanCalls, CloudCalls):
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
        it has none), its joint positions by name, its point clouds and its version."""
        r = self._call("GetScene", pb.GetSceneRequest(scene_id=scene_id))
        return Scene(
            scene_id=r.scene_id,
            name=r.name,
            instances=[Instance.from_proto(i) for i in r.instances],
            robot=SceneRobot.from_proto(r.robot) if r.HasField("robot") else None,
            joint_positions={j.name: j.position for j in r.joint_positions},
            point_clouds=[PointCloudInfo.from_proto(c) for c in r.point_clouds],
            scene_version=int(r.scene_version),
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
