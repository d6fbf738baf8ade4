"""Robot answer types: a robot's summary, configuration and motion checks in numpy columns, and the
robot of a scene. Units: radians for revolute and continuous joints, meters for prismatic joints,
distances and points.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import numpy as np

from .poses import Pose
from ._convert import _columns, _enum_name, _pose, _primitive_dict


@dataclass
class SceneRobot:
    """The robot placed in a scene (``Client.set_scene_robot``; a scene holds at most one).

    Attributes:
        robot_id: the stored robot.
        base: the pose of its root link in the scene (:class:`Pose`, meters).
        attached: the objects attached to its links, in attachment order, each a dict in the form
            ``Client.check_configurations`` and ``Client.attach_object`` take: ``{"link", "name",
            "kind", "size" / "radius" / "height", "origin"}`` (meters; ``origin`` a :class:`Pose`
            in the link's frame), so ``client.attach_object(scene, **robot.attached[0])``
            re-attaches one.
        link_padding: padding per link name (meters).
        joint_positions: the scene's joint positions of every joint of the robot, in
            :attr:`RobotInfo.joint_names` order (radians or meters; joints never set are 0).
    """

    robot_id: str
    base: Pose
    attached: List[Dict[str, object]] = field(default_factory=list)
    link_padding: Dict[str, float] = field(default_factory=dict)
    joint_positions: Dict[str, float] = field(default_factory=dict)

    @property
    def joint_names(self) -> List[str]:
        """The robot's joints in order (the keys of :attr:`joint_positions`)."""
        return list(self.joint_positions)

    @property
    def q(self) -> np.ndarray:
        """The joint positions as a configuration, shape (dof,), in :attr:`joint_names` order."""
        return np.array(list(self.joint_positions.values()), dtype=float)

    @classmethod
    def from_proto(cls, m) -> "SceneRobot":
        attached = [
            {"link": a.link, "name": a.name, **_primitive_dict(a.primitive), "origin": _pose(a.origin, a.HasField("origin"))}
            for a in m.attached
        ]
        return cls(
            robot_id=m.robot_id,
            base=_pose(m.base, m.HasField("base")),
            attached=attached,
            link_padding={k: float(v) for k, v in sorted(m.link_padding.items())},
            joint_positions={j.name: j.position for j in m.joint_positions},
        )



@dataclass
class RobotInfo:
    """A stored robot (``RobotSummary``): what its configurations are made of.

    Attributes:
        robot_id, name: its id and name.
        joint_names: the configuration's entries in order (the URDF's revolute, continuous and
            prismatic joints that are not mimic joints); ``dof == len(joint_names)``.
        lower, upper: joint limits, shape (dof,), radians or meters (-inf / +inf for a continuous
            joint).
        link_names: the links with collision geometry, in URDF order.
        geometries: collision geometries (a link may have several).
        self_pairs: link pairs the self-collision check tests (the SRDF's disabled pairs and the
            pairs on one rigid body left out).
        fit_warnings: what the fit skipped in the SRDF, one line each naming the element (entries
            naming links the URDF lacks, skipped as MoveIt's SRDF loader skips them).
        rigid_pairs: ``(link_a, link_b)`` pairs of links joined by fixed joints (no joint moves
            them relative to each other) that the SRDF does not disable, never checked all the same.
    """

    robot_id: str
    name: str
    joint_names: List[str]
    lower: np.ndarray
    upper: np.ndarray
    link_names: List[str]
    geometries: int
    self_pairs: int
    fit_warnings: List[str] = field(default_factory=list)
    rigid_pairs: List[Tuple[str, str]] = field(default_factory=list)

    @property
    def dof(self) -> int:
        """The number of joints of a configuration."""
        return len(self.joint_names)

    @classmethod
    def from_proto(cls, m) -> "RobotInfo":
        return cls(
            robot_id=m.robot_id,
            name=m.name,
            joint_names=list(m.joint_names),
            lower=np.asarray(m.lower, dtype=float),
            upper=np.asarray(m.upper, dtype=float),
            link_names=list(m.link_names),
            geometries=m.geometries,
            self_pairs=m.self_pairs,
            fit_warnings=list(m.fit_warnings),
            rigid_pairs=[tuple(p.split(" ", 1)) for p in m.rigid_pairs],
        )


@dataclass
class ConfigurationColumns:
    """The answer of ``Client.check_configurations``: row c is configuration c of the request.

    Attributes:
        joint_names: the robot's joints, the columns of ``gradient`` (dof of them).
        collides: shape (N,), bool: the robot collides with the world or itself.
        world: shape (N,), bool: a robot geometry collides with a world object.
        self_collision: shape (N,), bool: two links of a checked self pair collide.
        distance: shape (N,), meters: with ``distance=True``, the minimum robot–world distance on
            the collision meshes (0 when the robot collides with the world, +inf with no world
            pair); NaN when not asked for.
        robot_link, robot_geometry, world_object: length-N lists of str: the world pair of
            ``distance`` (or the colliding one): the link, its geometry (the link's name, ``#k``
            for its k-th geometry, k >= 1) and the world object; empty strings when none.
        witnesses: shape (N, 2, 3), meters, world frame: the closest points of that pair, the
            robot's (``[:, 0]``) and the object's (``[:, 1]``); NaN when the robot collides with
            the world or no distance was computed.
        self_link_a, self_link_b: length-N lists of str: a colliding self pair's links, else "".
        gradient: shape (N, dof): d distance / d q (meters per radian or per meter) with
            ``gradient=True``, NaN where the robot collides with the world or has no world pair;
            None when not asked for.
        converged: shape (N,), bool: every solve the answer rests on converged.
        pairs_pruned, pairs_model, pairs_exact: pairs decided by bounding volumes, bounded by the
            sos bodies, and resolved on the meshes, summed over the configurations.
        scene_version: the version of the scene checked against (its instances, robot, joint
            positions and point clouds as of that version; compare with
            ``Client.update_point_cloud``'s); 0 without a scene.
        fidelity: length-N list of str: the model each verdict rests on, "mesh" for the meshes'
            own (every free verdict, and a collision found on the meshes), else the conservative
            level asked for, whose bodies came within the padding (the meshes may be free there).
    """

    joint_names: List[str]
    collides: np.ndarray
    world: np.ndarray
    self_collision: np.ndarray
    distance: np.ndarray
    robot_link: List[str]
    robot_geometry: List[str]
    world_object: List[str]
    witnesses: np.ndarray
    self_link_a: List[str]
    self_link_b: List[str]
    gradient: Optional[np.ndarray]
    converged: np.ndarray
    pairs_pruned: int
    pairs_model: int
    pairs_exact: int
    scene_version: int = 0
    fidelity: List[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.collides)

    @classmethod
    def from_proto(cls, m, gradient: bool = True) -> "ConfigurationColumns":
        n, dof = m.count, len(m.joint_names)
        distance = np.asarray(m.distance, dtype=float)
        if distance.size == 0:
            distance = np.full(n, np.nan)
        return cls(
            joint_names=list(m.joint_names),
            collides=np.asarray(m.collides, dtype=bool),
            world=np.asarray(m.world, dtype=bool),
            self_collision=np.asarray(m.self_collision, dtype=bool),
            distance=distance,
            robot_link=list(m.robot_link),
            robot_geometry=list(m.robot_geometry),
            world_object=list(m.world_object),
            witnesses=_columns(m.witnesses, n, 6).reshape(n, 2, 3),
            self_link_a=list(m.self_link_a),
            self_link_b=list(m.self_link_b),
            gradient=_columns(m.gradient, n, dof) if gradient else None,
            converged=np.asarray(m.converged, dtype=bool),
            pairs_pruned=m.pairs_pruned,
            pairs_model=m.pairs_model,
            pairs_exact=m.pairs_exact,
            scene_version=int(m.scene_version),
            fidelity=list(m.fidelity) or ["mesh"] * n,
        )


def _counts(values, count: int) -> np.ndarray:
    """An integer column of ``count`` rows: zeros when the server sent none (a server older than
    the column)."""
    column = np.asarray(values, dtype=np.int64)
    return column if column.size == count else np.zeros(count, dtype=np.int64)


@dataclass
class MotionColumns:
    """The answer of ``Client.check_motions``: row m is the motion from ``q0[m]`` to ``q1[m]``.

    Attributes:
        joint_names: the robot's joints, the columns of ``contact_configuration`` (dof of them).
        valid: shape (M,), bool: the whole motion is proven free.
        decided: shape (M,), bool: false when the step limit was reached (then ``valid`` is false).
        contact_t: shape (M,): the first contact parameter t* in [0, 1] (within the tolerance);
            NaN when none.
        contact_configuration: shape (M, dof): the configuration at t* (radians, meters); NaN
            rows when none.
        robot_link: length-M list of str: the robot link in contact at t*, "" when none.
        other: length-M list of str: the world object in contact, or the other link of a self
            contact; "" when none.
        self_contact: shape (M,), bool: the contact at t* is a self contact.
        steps: shape (M,), int: advancement steps taken (configurations bounded); 0 for a
            sampled check.
        samples: shape (M,), int: samples checked by a sampled check (``resolution`` > 0; it
            stops at its first block of samples holding a colliding one); 0 for a certified one.

    Also ``scene_version``: the version of the scene checked against (as in
    :class:`ConfigurationColumns`); 0 without a scene.

    A sampled check's ``valid`` means no sample collides, its ``contact_t`` is a colliding
    sample's t and ``contact_configuration``, ``robot_link``, ``other``, ``self_contact`` are that
    sample's; it can miss a collision between samples, which the certified check cannot.
    """

    joint_names: List[str]
    valid: np.ndarray
    decided: np.ndarray
    contact_t: np.ndarray
    contact_configuration: np.ndarray
    robot_link: List[str]
    other: List[str]
    self_contact: np.ndarray
    steps: np.ndarray
    samples: np.ndarray
    scene_version: int = 0

    def __len__(self) -> int:
        return len(self.valid)

    @classmethod
    def from_proto(cls, m) -> "MotionColumns":
        n, dof = m.count, len(m.joint_names)
        contact_t = np.asarray(m.contact_t, dtype=float)
        if contact_t.size == 0:
            contact_t = np.full(n, np.nan)
        return cls(
            joint_names=list(m.joint_names),
            valid=np.asarray(m.valid, dtype=bool),
            decided=np.asarray(m.decided, dtype=bool),
            contact_t=contact_t,
            contact_configuration=_columns(m.contact_configuration, n, dof),
            robot_link=list(m.robot_link),
            other=list(m.other),
            self_contact=np.asarray(m.self_contact, dtype=bool),
            steps=np.asarray(m.steps, dtype=np.int64),
            samples=_counts(m.samples, n),
            scene_version=int(m.scene_version),
        )


#: ``PlanResponse.status`` names as :attr:`PlanResult.status` gives them.
PLAN_STATUSES = ("solved", "timed_out", "start_in_collision", "goal_in_collision", "goal_unreachable", "cancelled")


@dataclass
class JointTrajectory:
    """A timed trajectory of a plan (``Client.plan(..., trajectory=True)``; docs/planning.md,
    "Timed trajectories"), as MoveIt's ``trajectory_msgs/JointTrajectory``: P points of the n
    joints of :attr:`joint_names`, at rest at the first and the last, within the velocity and
    acceleration limits it was timed with. Units: radians (meters for prismatic joints) and
    seconds.

    Attributes:
        joint_names: the n joints, the columns of ``q``, ``qd`` and ``qdd``.
        t: shape (P,): seconds from the start (``time_from_start``), increasing, first 0, last
            ``duration``.
        q, qd, qdd: shape (P, n): positions, velocities, accelerations.
        duration: seconds from rest at the start to rest at the goal.
        max_velocity, max_acceleration: shape (n,): the limits it was timed within, scaling
            applied.
        certified: every piece of the geometry it sweeps (the path's straight pieces and the
            arcs blending its corners) is proven free at the plan's padding.
        blends: corners blended by an arc (each proven free); blends_tightened: corners whose
            blend was tightened to be proven; stops: corners where the robot comes to rest.
        seconds: the server's time for the trajectory stage.
        corner_deviation: shape (W,): per waypoint of the path it times (consecutive repeats
            dropped), the joint-space distance its corner's blend passes from it (0 at the ends,
            at stops and on straight runs): with the waypoints, the timed geometry exactly.
        warnings: from ``Client.time_trajectory``, what the server assumed or skipped, one line
            each naming the field (limits that took defaults); from a plan, empty (the plan's
            :attr:`PlanResult.warnings` hold them).
    """

    joint_names: List[str]
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    duration: float
    max_velocity: np.ndarray
    max_acceleration: np.ndarray
    certified: bool
    blends: int
    blends_tightened: int
    stops: int
    seconds: float
    corner_deviation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    warnings: List[str] = field(default_factory=list)

    @classmethod
    def from_proto(cls, m) -> "JointTrajectory":
        n = len(m.joint_names)
        rows = lambda v: np.asarray(v, dtype=float).reshape(-1, n)  # noqa: E731
        return cls(
            joint_names=list(m.joint_names),
            t=np.asarray(m.time_from_start, dtype=float),
            q=rows(m.positions),
            qd=rows(m.velocities),
            qdd=rows(m.accelerations),
            duration=float(m.duration),
            max_velocity=np.asarray(m.max_velocity, dtype=float),
            max_acceleration=np.asarray(m.max_acceleration, dtype=float),
            certified=bool(m.certified),
            blends=int(m.blends),
            blends_tightened=int(m.blends_tightened),
            stops=int(m.stops),
            seconds=float(m.seconds),
            corner_deviation=np.asarray(m.corner_deviation, dtype=float),
        )


@dataclass
class PlanResult:
    """The answer of ``Client.plan``: a path from the start to a goal whose every edge is proven
    free by conservative advancement (docs/planning.md). Units: radians for revolute and continuous
    joints, meters for prismatic ones, seconds for times.

    Attributes:
        status: how the plan ended: ``"solved"`` (a path, every edge certified), ``"timed_out"``
            (no path in time, or a path with unproven edges: ``certified`` false), or, with no
            path, ``"start_in_collision"`` / ``"goal_in_collision"`` (``message`` names the pair),
            ``"goal_unreachable"`` (no inverse-kinematics solution of a pose goal; ``message`` says
            why) or ``"cancelled"``.
        message: the colliding pair or the reason, in words; "" when solved.
        joint_names: the robot's joints, the columns of ``path`` and ``goal`` (n of them).
        path: shape (W, n): the waypoints, start first, the goal configuration reached last;
            shape (0, n) when there is no path.
        length: the path's joint-space length, the sum of its edges' Euclidean lengths
            (continuous joints the shorter way); 0 with no path.
        certified: every edge ``path[i] -> path[i + 1]`` is proven free at the request's padding
            by conservative advancement, at the contact tolerance or else at a hundredth of it
            (``Client.check_motions(..., tolerance=tolerance / 100)`` proves each such edge).
        unproven_edges: shape (E,), int: the edges left unproven (only when ``certified`` is
            false and there is a path).
        goal: shape (n,): the goal configuration reached; None when none was.
        timing: seconds per stage: ``goals`` (the start checked, goal configurations made),
            ``search`` (RRT-Connect), ``simplify``, ``certify`` (certificates and repairs) and
            ``total`` (the whole call on the server).
        states_checked, edges_checked: configurations checked, and edges checked by sampling.
        edges_certified, advancement_steps: edges checked by conservative advancement and their
            advancement steps.
        nodes: nodes of the search's two trees.
        repaired: edges the certification repaired (split or re-planned).
        scene_version: the version of the scene planned in (as in :class:`ConfigurationColumns`);
            0 without a scene.
        warnings: what the server changed in the request to plan it, one line each naming the
            field: start values moved into the joint limits (``start_state_max_bounds_error``),
            goal constraints outside the limits taken where their tolerance meets them.
        planning_joints: the joints the plan moved (the request's, or the goal's); the others stay
            at the start's values on every waypoint.
        trajectory: the path timed (:class:`JointTrajectory`) when the plan asked for one and
            found a path; else None.
    """

    status: str
    message: str
    joint_names: List[str]
    path: np.ndarray
    length: float
    certified: bool
    unproven_edges: np.ndarray
    goal: Optional[np.ndarray]
    timing: Dict[str, float]
    states_checked: int
    edges_checked: int
    edges_certified: int
    advancement_steps: int
    nodes: int
    repaired: int
    scene_version: int = 0
    warnings: List[str] = field(default_factory=list)
    planning_joints: List[str] = field(default_factory=list)
    trajectory: Optional[JointTrajectory] = None

    @property
    def solved(self) -> bool:
        """Whether the plan is solved: a path with every edge certified."""
        return self.status == "solved"

    @property
    def waypoints(self) -> int:
        """The number of waypoints of :attr:`path` (0 with no path)."""
        return int(self.path.shape[0])

    @classmethod
    def from_proto(cls, m) -> "PlanResult":
        from ._pb.sublevel.v1 import sublevel_pb2 as pb

        n = len(m.joint_names)
        path = np.asarray(m.path, dtype=float)
        path = path.reshape(-1, n) if n else np.zeros((0, 0))
        t = m.timing
        return cls(
            status=_enum_name(pb.PlanStatus, m.status, "PLAN_STATUS_").lower(),
            message=m.message,
            joint_names=list(m.joint_names),
            path=path,
            length=float(m.length),
            certified=bool(m.certified),
            unproven_edges=np.asarray(m.unproven_edges, dtype=np.int64),
            goal=np.asarray(m.goal, dtype=float) if len(m.goal) else None,
            timing={k: float(getattr(t, k)) for k in ("goals", "search", "simplify", "certify", "total")},
            states_checked=int(m.states_checked),
            edges_checked=int(m.edges_checked),
            edges_certified=int(m.edges_certified),
            advancement_steps=int(m.advancement_steps),
            nodes=int(m.nodes),
            repaired=int(m.repaired),
            scene_version=int(m.scene_version),
            warnings=list(m.warnings),
            planning_joints=list(m.planning_joints),
            trajectory=JointTrajectory.from_proto(m.trajectory) if m.HasField("trajectory") else None,
        )
