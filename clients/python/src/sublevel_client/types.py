"""Answer types: plain dataclasses with numpy arrays, parsed from the service's messages.

Units: points, witnesses, distances and translations in meters; squared distances (certificates
of distance queries) in m²; growth values d(p1 || p2) dimensionless (> 1 separated, <= 1
overlapping). Gradients are twists ``[vx, vy, vz, wx, wy, wz]`` of the pose perturbed on the left
in the world frame (value units per meter for v, per radian for w).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple, Union

import numpy as np

from .poses import Pose
from ._convert import _columns, _enum_name, _pose, _twist, _v3
from .clouds import PointCloudInfo
from .imported import AllowedCollisionMatrix, ImportedInstance, ImportedMesh, ImportedScene, SkippedShape
from .robot_types import ConfigurationColumns, JointTrajectory, MotionColumns, PlanResult, RobotInfo, SceneRobot

__all__ = [
    "SolveInfo",
    "Certificate",
    "DistanceAnswer",
    "GrowthAnswer",
    "CollideAnswer",
    "Answer",
    "StateAnswers",
    "AnswerColumns",
    "QueryResult",
    "ScenePair",
    "SceneCheck",
    "BodySummary",
    "SceneSummary",
    "Instance",
    "Scene",
    "SceneRobot",
    "UploadedBody",
    "AllowedCollisionMatrix",
    "ImportedInstance",
    "SkippedShape",
    "ImportedMesh",
    "ImportedScene",
    "RobotInfo",
    "ConfigurationColumns",
    "MotionColumns",
    "JointTrajectory",
    "PlanResult",
]


@dataclass
class SolveInfo:
    """Solver diagnostics of one answer.

    Attributes:
        converged: the answer is a certified optimum (converged Newton, or verified SDP).
        status: "CONVERGED", "MAX_ITERATIONS", "STALLED" or "UNSPECIFIED".
        iterations: Newton iterations over all phases.
        kkt_residual: final infinity-norm of the KKT residual.
        warm_started: the solve started from the cached warm start of this pair.
        precision_limited: the inputs (very large translations) limit the accuracy.
    """

    converged: bool
    status: str
    iterations: int
    kkt_residual: float
    warm_started: bool
    precision_limited: bool

    @classmethod
    def from_proto(cls, m) -> "SolveInfo":
        from ._pb.sublevel.v1 import sublevel_pb2 as pb

        return cls(
            converged=m.converged,
            status=_enum_name(pb.SolveStatus, m.status, "SOLVE_STATUS_"),
            iterations=m.iterations,
            kkt_residual=m.kkt_residual,
            warm_started=m.warm_started,
            precision_limited=m.precision_limited,
        )


@dataclass
class Certificate:
    """The level-0 sos certificate (an SDP) of a query, in the objective's units (m² for distance,
    dimensionless for growth). See the proto's ``Certificate``."""

    bound: float
    verified_bound: float
    agrees: bool
    relative_gap: float
    gram_min_eigenvalue: float
    solve_seconds: float
    verified: bool
    newton_value: float

    @classmethod
    def from_proto(cls, m) -> "Certificate":
        return cls(
            bound=m.bound,
            verified_bound=m.verified_bound,
            agrees=m.agrees,
            relative_gap=m.relative_gap,
            gram_min_eigenvalue=m.gram_min_eigenvalue,
            solve_seconds=m.solve_seconds,
            verified=m.verified,
            newton_value=m.newton_value,
        )


@dataclass
class TreeAnswer:
    """What a query involving a compound body (a containment tree of bodies) reports besides the
    answer: the branch and bound's bounds and cost (``TreeAnswer`` in the proto).

    Attributes:
        lower, upper: distance: bounds of the models' distance in meters (``distance`` is
            ``lower``); growth and collide: both the answer's value / deciding bound.
        level: the deepest tree level reached (0: the root pair decided).
        leaves: the active leaf pair ``(node of the first body, node of the second)``, or None.
        pairs_evaluated: node pairs solved; pairs_pruned_by_spheres: pairs decided by bounding
            spheres alone.
        within_tolerance: distance: upper - lower <= the tolerance asked for.
    """

    lower: float
    upper: float
    level: int
    leaves: Optional[Tuple[int, int]]
    pairs_evaluated: int
    pairs_pruned_by_spheres: int
    within_tolerance: bool

    @classmethod
    def from_proto(cls, m) -> "TreeAnswer":
        return cls(
            lower=m.lower,
            upper=m.upper,
            level=m.level,
            leaves=(m.leaves.node_a, m.leaves.node_b) if m.HasField("leaves") else None,
            pairs_evaluated=m.pairs_evaluated,
            pairs_pruned_by_spheres=m.pairs_pruned_by_spheres,
            within_tolerance=m.within_tolerance,
        )


def _tree(m) -> Optional[TreeAnswer]:
    return TreeAnswer.from_proto(m.tree) if m.HasField("tree") else None


@dataclass
class DistanceAnswer:
    """Euclidean distance between two posed bodies.

    Attributes:
        distance: meters; 0 when the bodies overlap or touch.
        witness_a, witness_b: closest points of A and B in world coordinates, shape (3,), meters.
        normal: unit normal from A towards B, shape (3,); zero when overlapping.
        overlapping: the bodies overlap or touch (for lower bounds: not proven separated).
        converged, iterations, kkt_residual: solver diagnostics (also in ``solve``).
        source: "NEWTON", "SDP_FALLBACK" or "SDP_LOWER_BOUND".
        lower_bound: ``distance`` is only a lower bound (a nonconvex body).
        tight: lower bounds only: the bound is attained, hence exact.
        gradient_a, gradient_b: d distance / d pose as twists ``[v, w]`` shape (6,) (with_gradient),
            else None.
        certificate: the SDP certificate on the squared distance (m²) when one was solved.
        solve: all solver diagnostics.
        signed_distance: with ``signed`` asked: meters, the distance when separated, minus the
            penetration depth when overlapping (0 when not asked, or for lower bounds).
        penetration_depth: with ``signed`` and overlapping: the minimum translation distance
            (meters, >= 0), the length of the shortest translation of B separating the bodies.
        penetration_normal: with ``signed`` and overlapping: the unit direction, shape (3,), from A
            to B along which translating B by penetration_depth separates them (else zero).
        signed_gradient_a, signed_gradient_b: with ``signed`` and ``with_gradient``: gradients of
            signed_distance as twists shape (6,), else None.
        tree: when either body is a compound body, the tree bounds (:class:`TreeAnswer`), else None.
    """

    distance: float
    witness_a: np.ndarray
    witness_b: np.ndarray
    normal: np.ndarray
    overlapping: bool
    converged: bool
    iterations: int
    kkt_residual: float
    source: str
    lower_bound: bool
    tight: bool
    gradient_a: Optional[np.ndarray]
    gradient_b: Optional[np.ndarray]
    certificate: Optional[Certificate]
    solve: SolveInfo
    signed_distance: float = 0.0
    penetration_depth: float = 0.0
    penetration_normal: np.ndarray = field(default_factory=lambda: np.zeros(3))
    signed_gradient_a: Optional[np.ndarray] = None
    signed_gradient_b: Optional[np.ndarray] = None
    tree: Optional[TreeAnswer] = None

    @property
    def warm_started(self) -> bool:
        """Whether the solve started from a cached warm start."""
        return self.solve.warm_started

    @classmethod
    def from_proto(cls, m) -> "DistanceAnswer":
        from ._pb.sublevel.v1 import sublevel_pb2 as pb

        solve = SolveInfo.from_proto(m.solve)
        return cls(
            distance=m.distance,
            witness_a=_v3(m.witness_a),
            witness_b=_v3(m.witness_b),
            normal=_v3(m.normal),
            overlapping=m.overlapping,
            converged=solve.converged,
            iterations=solve.iterations,
            kkt_residual=solve.kkt_residual,
            source=_enum_name(pb.AnswerSource, m.source, "ANSWER_SOURCE_"),
            lower_bound=m.lower_bound,
            tight=m.tight,
            gradient_a=_twist(m.gradient_a, m.HasField("gradient_a")),
            gradient_b=_twist(m.gradient_b, m.HasField("gradient_b")),
            certificate=Certificate.from_proto(m.certificate) if m.HasField("certificate") else None,
            solve=solve,
            signed_distance=m.signed_distance,
            penetration_depth=m.penetration_depth,
            penetration_normal=_v3(m.penetration_normal),
            signed_gradient_a=_twist(m.signed_gradient_a, m.HasField("signed_gradient_a")),
            signed_gradient_b=_twist(m.signed_gradient_b, m.HasField("signed_gradient_b")),
            tree=_tree(m),
        )


@dataclass
class GrowthAnswer:
    """Growth measure d(p1 || p2) = min p1(x) s.t. p2(x) <= 1 (dimensionless).

    Attributes:
        value: d(p1 || p2); <= 1 iff the bodies overlap.
        minimizer: the minimizer x* in world coordinates, shape (3,), meters.
        multiplier: multiplier of the constraint p2 <= 1 (0 when inactive).
        separated: value > 1 (for lower bounds: proven disjoint).
        converged, iterations, kkt_residual, source, lower_bound, tight, certificate, solve: as in
            :class:`DistanceAnswer`.
        gradient_1, gradient_2: d value / d pose of p1 / p2 as twists shape (6,), else None.
        tree: compound pairs: the tree bounds (value is then the smallest d over overlapping leaf
            pairs, +inf when none overlaps), else None.
    """

    value: float
    minimizer: np.ndarray
    multiplier: float
    separated: bool
    converged: bool
    iterations: int
    kkt_residual: float
    source: str
    lower_bound: bool
    tight: bool
    gradient_1: Optional[np.ndarray]
    gradient_2: Optional[np.ndarray]
    certificate: Optional[Certificate]
    solve: SolveInfo
    tree: Optional[TreeAnswer] = None

    @property
    def warm_started(self) -> bool:
        """Whether the solve started from a cached warm start."""
        return self.solve.warm_started

    @classmethod
    def from_proto(cls, m) -> "GrowthAnswer":
        from ._pb.sublevel.v1 import sublevel_pb2 as pb

        solve = SolveInfo.from_proto(m.solve)
        return cls(
            value=m.value,
            minimizer=_v3(m.minimizer),
            multiplier=m.multiplier,
            separated=m.separated,
            converged=solve.converged,
            iterations=solve.iterations,
            kkt_residual=solve.kkt_residual,
            source=_enum_name(pb.AnswerSource, m.source, "ANSWER_SOURCE_"),
            lower_bound=m.lower_bound,
            tight=m.tight,
            gradient_1=_twist(m.gradient_1, m.HasField("gradient_1")),
            gradient_2=_twist(m.gradient_2, m.HasField("gradient_2")),
            certificate=Certificate.from_proto(m.certificate) if m.HasField("certificate") else None,
            solve=solve,
            tree=_tree(m),
        )


@dataclass
class CollideAnswer:
    """Collide-with-margin: are the bodies closer than ``margin`` meters (or overlapping)?

    Attributes:
        collides: overlapping, or distance below the margin.
        distance: meters: the solved distance, or (decided_by_bounds) a certified lower bound
            from the bounding spheres or the separating axis, or 0 when a common point proved
            overlap.
        decided_by_bounds: the cheap tests decided, no solve ran: the bounding spheres, then
            the separating axis along the line between the bodies (clear of the margin), then
            a point of both bodies on the segment between their interior points (overlap).
        margin: the margin asked for, meters.
        solve: the distance solve's diagnostics when one ran, else None.
        tree: compound pairs: the tree level that decided and the deciding bound, else None.
    """

    collides: bool
    distance: float
    decided_by_bounds: bool
    margin: float
    solve: Optional[SolveInfo]
    tree: Optional[TreeAnswer] = None

    @property
    def warm_started(self) -> bool:
        """Whether the distance solve (if any) started from a cached warm start."""
        return bool(self.solve and self.solve.warm_started)

    @classmethod
    def from_proto(cls, m) -> "CollideAnswer":
        return cls(
            collides=m.collides,
            distance=m.distance,
            decided_by_bounds=m.decided_by_bounds,
            margin=m.margin,
            solve=SolveInfo.from_proto(m.solve) if m.HasField("solve") else None,
            tree=_tree(m),
        )


Answer = Union[DistanceAnswer, GrowthAnswer, CollideAnswer]


def answer_from_proto(m) -> Answer:
    """One ``QueryAnswer`` as the dataclass of its kind."""
    which = m.WhichOneof("answer")
    if which == "distance":
        return DistanceAnswer.from_proto(m.distance)
    if which == "growth":
        return GrowthAnswer.from_proto(m.growth)
    if which == "collide":
        return CollideAnswer.from_proto(m.collide)
    raise ValueError(f"empty QueryAnswer from the server: {m!r}")


@dataclass
class StateAnswers:
    """The answers of one candidate state, one per query in order.

    Attributes:
        answers: one answer per query.
        any_collision: any COLLIDE query of this state collides.
        columns: the answers in columns (requests in columns).
    """

    answers: List[Answer]
    any_collision: bool
    columns: Optional["AnswerColumns"] = None

    @classmethod
    def from_proto(cls, m) -> "StateAnswers":
        return cls(
            answers=[answer_from_proto(a) for a in m.answers],
            any_collision=m.any_collision,
            columns=AnswerColumns.from_proto(m.columns) if m.HasField("columns") else None,
        )


@dataclass
class AnswerColumns:
    """Answers in columns (``BatchQueryResponse.columns``, ``QueryResponse.columns``): row k is
    pair k of the request.

    Attributes:
        kind: ``"distance"``, ``"growth"`` or ``"collide"``.
        value: shape (n,). Distance: meters (0 when overlapping). Growth: d(p1 || p2).
            Collide: the distance in meters, or when ``decided_by_bounds`` the cheap bounds'
            certified lower bound (clear) or 0 (a common point proved overlap).
        point_a: shape (n, 3), meters, world frame: the witness on the first body (growth: the
            minimizer); NaN when no solve ran (collide decided by bounds).
        point_b: shape (n, 3): the witness on the second body (growth: the minimizer again).
        converged: shape (n,), bool: a converged Newton answer or a verified SDP answer.
        overlapping: shape (n,), bool: the bodies overlap (collide: the verdict, closer than the
            margin or overlapping).
        lower_bound: shape (n,), bool: the value is only a lower bound (nonconvex body).
        decided_by_bounds: shape (n,), bool for collide (the cheap tests decided, no solve:
            bounding spheres or separating axis clear it, or a common point proves overlap);
            empty for other kinds.
    """

    kind: str
    value: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray
    converged: np.ndarray
    overlapping: np.ndarray
    lower_bound: np.ndarray
    decided_by_bounds: np.ndarray

    def __len__(self) -> int:
        return len(self.value)

    @classmethod
    def from_proto(cls, m) -> "AnswerColumns":
        from ._pb.sublevel.v1 import sublevel_pb2 as pb

        return cls(
            kind=_enum_name(pb.QueryKind, m.kind, "QUERY_KIND_").lower(),
            value=np.asarray(m.value, dtype=float),
            point_a=np.asarray(m.point_a, dtype=float).reshape(-1, 3),
            point_b=np.asarray(m.point_b, dtype=float).reshape(-1, 3),
            converged=np.asarray(m.converged, dtype=bool),
            overlapping=np.asarray(m.overlapping, dtype=bool),
            lower_bound=np.asarray(m.lower_bound, dtype=bool),
            decided_by_bounds=np.asarray(m.decided_by_bounds, dtype=bool),
        )


@dataclass
class QueryResult:
    """The response of a planner request (Query, one QueryStream message).

    Attributes:
        answers: one answer per query (requests without states).
        states: one :class:`StateAnswers` per candidate state (requests with states).
        server_seconds: seconds the server spent (not the transport).
        request_id: the request's id, echoed.
        columns: the answers in columns (requests in columns without states).
        robot_states: the answers of the request's joint configurations (requests with
            ``robot_states``), else None.
        robot_motions: the answers of the request's joint-space motions (requests with
            ``robot_motions``), else None.
    """

    answers: List[Answer]
    states: List[StateAnswers]
    server_seconds: float
    request_id: int
    columns: Optional["AnswerColumns"] = None
    robot_states: Optional["ConfigurationColumns"] = None
    robot_motions: Optional["MotionColumns"] = None

    @classmethod
    def from_proto(cls, m, gradient: Optional[bool] = None) -> "QueryResult":
        """``gradient``: whether ``robot_states.gradient`` was asked for (None: when the server
        sent one)."""
        robot_states = None
        if m.HasField("robot_states"):
            grad = len(m.robot_states.gradient) > 0 if gradient is None else gradient
            robot_states = ConfigurationColumns.from_proto(m.robot_states, gradient=grad)
        return cls(
            answers=[answer_from_proto(a) for a in m.answers],
            states=[StateAnswers.from_proto(s) for s in m.states],
            columns=AnswerColumns.from_proto(m.columns) if m.HasField("columns") else None,
            server_seconds=m.server_seconds,
            request_id=m.request_id,
            robot_states=robot_states,
            robot_motions=MotionColumns.from_proto(m.robot_motions) if m.HasField("robot_motions") else None,
        )


@dataclass
class ScenePair:
    """A pair found by CheckScene: ``first`` < ``second`` (by id) and their distance answer."""

    first: str
    second: str
    distance: DistanceAnswer

    @classmethod
    def from_proto(cls, m) -> "ScenePair":
        return cls(first=m.first, second=m.second, distance=DistanceAnswer.from_proto(m.distance))


@dataclass
class SceneCheck:
    """The response of CheckScene.

    Attributes:
        pairs: pairs that overlap or lie within the margin, ordered by distance.
        instances: instances checked.
        candidate_pairs: pairs passing the broad phase (posed boxes grown by the margin).
        narrow_phase_solves: distance solves run.
        all_pairs: pairs a brute-force check would have examined.
        server_seconds: seconds the server spent.
        robot: the scene's robot (``Client.set_scene_robot``) at the scene's joint positions,
            checked against the scene's objects (at the check's poses) and itself with the
            check's margin as padding, with its distance: :class:`ConfigurationColumns` of one
            row. None when the scene has no robot.
        scene_version: the version of the scene checked (its instances, poses and point clouds).

    A pair with a point cloud has the instance as ``first`` and the cloud's name as ``second``,
    with the distance to the cloud's nearest point ball.
    """

    pairs: List[ScenePair]
    instances: int
    candidate_pairs: int
    narrow_phase_solves: int
    all_pairs: int
    server_seconds: float
    robot: Optional["ConfigurationColumns"] = None
    scene_version: int = 0

    @classmethod
    def from_proto(cls, m) -> "SceneCheck":
        return cls(
            pairs=[ScenePair.from_proto(p) for p in m.pairs],
            instances=m.instances,
            candidate_pairs=m.candidate_pairs,
            narrow_phase_solves=m.narrow_phase_solves,
            all_pairs=m.all_pairs,
            server_seconds=m.server_seconds,
            robot=ConfigurationColumns.from_proto(m.robot, gradient=False) if m.HasField("robot") else None,
            scene_version=int(m.scene_version),
        )


@dataclass
class UploadedBody:
    """The response of UploadBody: the body's id, whether it is stored as nonconvex, and its
    certified sos-convexity margin (NaN when not checked)."""

    body_id: str
    nonconvex: bool
    convexity_margin: float
    nodes: int = 1


@dataclass
class BodySummary:
    """A stored body without its coefficients (volume in m³; 0 when unknown). For an exact
    primitive, ``primitive`` is its kind (``"box"``, ``"sphere"``, ``"cylinder"``, ``"capsule"``,
    ``"halfspace"``), ``degree`` 0 and ``method`` ``"primitive"``; empty for a fitted body."""

    body_id: str
    name: str
    degree: int
    method: str
    volume: float
    primitive: str = ""


@dataclass
class SceneSummary:
    """A stored scene without its instances."""

    scene_id: str
    name: str
    num_instances: int


@dataclass
class Instance:
    """An instance of a body in a scene under a pose."""

    instance_id: str
    body_id: str
    pose: Pose

    @classmethod
    def from_proto(cls, m) -> "Instance":
        return cls(instance_id=m.instance_id, body_id=m.body_id, pose=_pose(m.pose, m.HasField("pose")))


@dataclass
class Scene:
    """A scene with its instances (ordered by id), its robot and its joint positions.

    Attributes:
        scene_id, name: the scene.
        instances: its instances with their stored poses.
        robot: its robot (:class:`SceneRobot`), None when it has none.
        joint_positions: the scene's robot state by joint name (radians or meters): set by
            ``Client.import_scene``, ``Client.set_scene_robot`` and ``Client.set_joint_positions``;
            it stays when the robot is removed.
        point_clouds: its point clouds (``Client.update_point_cloud``), ordered by name: in the
            server's memory only (a restarted server has none until the sensor sends again).
        scene_version: the scene version this answer was read at.
    """

    scene_id: str
    name: str
    instances: List[Instance] = field(default_factory=list)
    robot: Optional[SceneRobot] = None
    joint_positions: Dict[str, float] = field(default_factory=dict)
    point_clouds: List[PointCloudInfo] = field(default_factory=list)
    scene_version: int = 0

    def instance(self, instance_id: str) -> Instance:
        """The instance with this id (KeyError if absent)."""
        for i in self.instances:
            if i.instance_id == instance_id:
                return i
        raise KeyError(instance_id)

    def by_body(self) -> Dict[str, List[str]]:
        """Instance ids grouped by body id."""
        out: Dict[str, List[str]] = {}
        for i in self.instances:
            out.setdefault(i.body_id, []).append(i.instance_id)
        return out


@dataclass
class InstanceMotionColumns:
    """The answer of ``Client.check_instance_motions``: row m is the motion of
    ``instance_ids[m]`` from ``start_poses[m]`` to ``end_poses[m]``.

    Attributes:
        valid: shape (M,), bool: the whole motion is proven free.
        decided: shape (M,), bool: false when the step limit was reached or a contact could not be
            proven within the tolerance (then ``valid`` is false and there is no contact).
        contact_t: shape (M,): the first contact parameter t* in [0, 1] (within the tolerance:
            free before it); NaN when none.
        contact_pose: shape (M, 7): the moving instance's pose at t* (w, x, y, z, tx, ty, tz;
            meters); NaN rows when none.
        other: length-M list of str: the instance it comes into contact with; "" when none.
        steps: shape (M,), int: advancement steps taken (poses bounded).
    """

    valid: np.ndarray
    decided: np.ndarray
    contact_t: np.ndarray
    contact_pose: np.ndarray
    other: List[str]
    steps: np.ndarray

    def __len__(self) -> int:
        return len(self.valid)

    @classmethod
    def from_proto(cls, m) -> "InstanceMotionColumns":
        n = m.count
        contact_t = np.asarray(m.contact_t, dtype=float)
        if contact_t.size == 0:
            contact_t = np.full(n, np.nan)
        return cls(
            valid=np.asarray(m.valid, dtype=bool),
            decided=np.asarray(m.decided, dtype=bool),
            contact_t=contact_t,
            contact_pose=_columns(m.contact_pose, n, 7),
            other=list(m.other),
            steps=np.asarray(m.steps, dtype=np.int64),
        )
