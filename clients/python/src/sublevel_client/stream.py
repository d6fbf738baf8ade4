"""One QueryStream kept open for a planner loop: :class:`PlannerStream`."""

from __future__ import annotations

import queue
import threading
from typing import TYPE_CHECKING, Any, Iterable, Iterator, List, Mapping, Optional, Sequence, Union

import grpc

from ._pb.sublevel.v1 import sublevel_pb2 as pb
from .errors import SublevelError
from .types import (
    Answer,
    AnswerColumns,
    ConfigurationColumns,
    MotionColumns,
    QueryResult,
    StateAnswers,
)
from ._requests import (
    PosesLike,
    SCENE_ID_HEADER,
    _instance_poses,
    _pair_columns,
    _planner_queries,
    _state_columns_query,
    _states,
)

if TYPE_CHECKING:
    from .client import Client

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
        resolution: float = 0.0,
    ) -> MotionColumns:
        """Certifies (or, with ``resolution`` > 0, samples) joint-space motions ``q0[m] -> q1[m]``
        against the stream's view of the scene (after ``poses`` are applied to it and kept): one
        request with ``QueryRequest.robot_motions``. The arguments and the answer are those of
        :meth:`Client.check_motions`; ``robot``, ``joint_names`` and errors as in
        :meth:`check_configurations` (fields prefixed ``robot_motions.``).
        """
        req = self._client._motions_request(
            robot, q0, q1, scene=self.scene, joint_names=joint_names, base=base, padding=padding,
            tolerance=tolerance, max_steps=max_steps, attached=attached, link_padding=link_padding,
            scene_joints=self._scene_robot_joints, resolution=resolution,
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
