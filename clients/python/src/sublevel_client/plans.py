"""The planning call of :class:`~sublevel_client.Client`: ``Plan``, a robot's path among a scene in
one call (RRT-Connect, simplification, every edge certified by conservative advancement;
docs/planning.md), its arguments checked here (ValueError naming the argument) before anything is
sent.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from ._pb.sublevel.v1 import sublevel_pb2 as pb
from ._requests import (
    _attached_pb,
    _configuration_columns,
    _configurations,
    _fidelity_pb,
    _link_padding,
    _pose_pb,
)
from .robot_types import JointTrajectory, PlanResult

#: Seconds the gRPC deadline of :meth:`PlanCalls.plan` leaves beyond the plan's ``timeout`` by
#: default, so that the server answers ``timed_out`` itself (with its partial figures) rather than
#: the call failing with DEADLINE_EXCEEDED.
PLAN_DEADLINE_MARGIN = 5.0

_POSE_GOAL_KEYS = ("link", "pose", "position_tolerance", "orientation_tolerance")


def _real(value: Any, name: str, *, low: float = -math.inf, low_open: bool = False, high: float = math.inf,
          high_open: bool = False, what: str = "") -> float:
    """``value`` as a finite float in the interval; ValueError naming ``name`` otherwise."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"`{name}`: expected a number{what}, got {value!r}") from None
    inside = math.isfinite(v) and (v > low if low_open else v >= low) and (v < high if high_open else v <= high)
    if not inside:
        if math.isinf(low) and math.isinf(high):
            raise ValueError(f"`{name}`: expected a finite number{what}, got {value!r}")
        lo = "(" if low_open else "["
        hi = ")" if high_open else "]"
        raise ValueError(f"`{name}`: expected a finite number in {lo}{low:g}, {high:g}{hi}{what}, got {value!r}")
    return v


def _integer(value: Any, name: str, low: int, high: int = 2**64 - 1) -> int:
    """``value`` as an int in [low, high]; ValueError naming ``name`` otherwise (bools refused)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"`{name}`: expected an integer, got {value!r}")
    if not low <= int(value) <= high:
        raise ValueError(f"`{name}`: expected an integer in [{low}, {high}], got {value!r}")
    return int(value)


def _plan_settings(
    timeout: float,
    seed: Optional[int],
    range: Optional[float],  # noqa: A002 (the setting's name)
    padding: float,
    simplify: bool,
    smoothing_passes: int,
    resolution: Optional[float],
    goal_bias: Optional[float],
    tolerance: Optional[float],
    max_goals: Optional[int],
    start_state_max_bounds_error: Optional[float] = None,
) -> pb.PlanSettings:
    """The ``PlanSettings`` of :meth:`PlanCalls.plan` (same arguments; None: the server's default)."""
    s = pb.PlanSettings(
        timeout=_real(timeout, "timeout", low=0.0, low_open=True, high=3600.0, what=" of seconds"),
        padding=_real(padding, "padding", low=0.0, high=1.0, what=" of meters"),
        simplify=bool(simplify),
        smoothing_passes=_integer(smoothing_passes, "smoothing_passes", 0, 8),
    )
    if seed is not None:
        s.seed = _integer(seed, "seed", 0)
    if range is not None:
        s.range = _real(range, "range", low=0.0, low_open=True, what=" (joint-space distance)")
    if resolution is not None:
        s.resolution = _real(
            resolution, "resolution", low=0.0, low_open=True, high=1000.0, what=" of configurations per unit"
        )
    if goal_bias is not None:
        s.goal_bias = _real(goal_bias, "goal_bias", low=0.0, high=1.0, high_open=True)
    if tolerance is not None:
        s.tolerance = _real(tolerance, "tolerance", low=0.0, low_open=True, high=0.1, what=" of meters")
    if max_goals is not None:
        s.max_goals = _integer(max_goals, "max_goals", 1, 64)
    if start_state_max_bounds_error is not None:
        s.start_state_max_bounds_error = _real(
            start_state_max_bounds_error, "start_state_max_bounds_error", low=0.0, high=1.0,
            what=" (radians or meters)"
        )
    return s


def _trajectory_settings(
    sample_dt: Optional[float],
    velocity_scaling: Optional[float],
    acceleration_scaling: Optional[float],
    max_deviation: Optional[float],
    max_velocity: Optional[Mapping[str, float]],
    max_acceleration: Optional[Mapping[str, float]],
    joint_limits: Any,
) -> pb.TrajectorySettings:
    """The ``TrajectorySettings`` of :meth:`PlanCalls.plan` (same arguments; None: the server's
    default); ValueError naming the argument when one is malformed."""
    s = pb.TrajectorySettings()
    if sample_dt is not None:
        s.sample_dt = _real(sample_dt, "sample_dt", low=0.0, low_open=True, what=" of seconds")
    if velocity_scaling is not None:
        s.velocity_scaling = _real(velocity_scaling, "velocity_scaling", low=0.0, low_open=True, high=1.0)
    if acceleration_scaling is not None:
        s.acceleration_scaling = _real(acceleration_scaling, "acceleration_scaling", low=0.0, low_open=True, high=1.0)
    if max_deviation is not None:
        s.max_deviation = _real(max_deviation, "max_deviation", low=0.0, what=" (radians or meters)")
    for name, limits, target in (("max_velocity", max_velocity, s.max_velocity),
                                 ("max_acceleration", max_acceleration, s.max_acceleration)):
        if limits is None:
            continue
        if not isinstance(limits, Mapping):
            raise ValueError(f"`{name}`: expected a mapping of joint name to limit, got {type(limits).__name__}")
        for joint, v in limits.items():
            target[str(joint)] = _real(v, f"{name}[{joint}]", low=0.0, low_open=True)
    if joint_limits is not None:
        if isinstance(joint_limits, os.PathLike):
            text = Path(joint_limits).read_text(encoding="utf-8")
        elif isinstance(joint_limits, str):
            one_line = "\n" not in joint_limits
            text = (Path(joint_limits).read_text(encoding="utf-8")
                    if one_line and os.path.isfile(joint_limits) else joint_limits)
        else:
            raise ValueError(f"`joint_limits`: expected YAML text or a path, got {type(joint_limits).__name__}")
        s.joint_limits_yaml = text
    return s


def _motion_plan_request(request: Any) -> Tuple[str, str]:
    """``("yaml" | "json", text)`` of a MoveIt MotionPlanRequest given as text (JSON when it starts
    with ``{``), bytes, a mapping (sent as JSON), or a path (``os.PathLike``, or a one-line
    ``str`` naming an existing file). ValueError naming ``motion_plan_request`` otherwise."""
    name = "motion_plan_request"
    if isinstance(request, Mapping):
        text = json.dumps(request)
    elif isinstance(request, (bytes, bytearray, memoryview)):
        text = bytes(request).decode("utf-8")
    elif isinstance(request, os.PathLike):
        text = Path(request).read_text(encoding="utf-8")
    elif isinstance(request, str):
        one_line = "\n" not in request and not request.lstrip().startswith("{")
        text = Path(request).read_text(encoding="utf-8") if one_line and os.path.isfile(request) else request
    else:
        raise ValueError(f"`{name}`: expected YAML or JSON text, a path or a mapping, got {type(request).__name__}")
    if not text.strip():
        raise ValueError(f"`{name}`: empty")
    return ("json" if text.lstrip().startswith("{") else "yaml"), text


def _joint_constraints(goal_joints: Any) -> List[pb.JointConstraint]:
    """``JointConstraint`` messages of ``{joint: position}`` or ``{joint: (position,
    tolerance_below, tolerance_above)}`` (radians or meters). ValueError naming
    ``goal_joints[joint]``."""
    if not isinstance(goal_joints, Mapping):
        raise ValueError(f"`goal_joints`: expected a mapping {{joint name: position}}, got {type(goal_joints).__name__}")
    if not goal_joints:
        raise ValueError("`goal_joints`: no joint")
    out = []
    for joint, value in goal_joints.items():
        if not isinstance(joint, str) or not joint:
            raise ValueError(f"`goal_joints`: joint names must be non-empty strings, got {joint!r}")
        name = f"goal_joints[{joint}]"
        if isinstance(value, (tuple, list, np.ndarray)):
            if len(value) != 3:
                raise ValueError(f"`{name}`: expected a position or (position, tolerance_below, tolerance_above), got {value!r}")
            position, below, above = value
        else:
            position, below, above = value, 0.0, 0.0
        out.append(
            pb.JointConstraint(
                joint_name=joint,
                position=_real(position, f"{name}", what=" (the position)"),
                tolerance_below=_real(below, f"{name}", low=0.0, what=" (tolerance_below)"),
                tolerance_above=_real(above, f"{name}", low=0.0, what=" (tolerance_above)"),
            )
        )
    return out


def _pose_goal(goal_pose: Any) -> pb.PoseGoal:
    """The ``PoseGoal`` of ``{"link", "pose", "position_tolerance", "orientation_tolerance"}``.
    ValueError naming ``goal_pose.KEY``."""
    if not isinstance(goal_pose, Mapping):
        raise ValueError(f"`goal_pose`: expected a dict with `link` and `pose`, got {type(goal_pose).__name__}")
    unknown = sorted(set(goal_pose) - set(_POSE_GOAL_KEYS))
    if unknown:
        raise ValueError(f"`goal_pose`: unknown keys {unknown}; expected {list(_POSE_GOAL_KEYS)}")
    link = goal_pose.get("link")
    if not isinstance(link, str) or not link:
        raise ValueError(f"`goal_pose.link`: required: the link's URDF name, got {link!r}")
    if goal_pose.get("pose") is None:
        raise ValueError("`goal_pose.pose`: required: the link's pose in the world")
    return pb.PoseGoal(
        link=link,
        pose=_pose_pb(goal_pose["pose"], "goal_pose.pose"),
        position_tolerance=_real(goal_pose.get("position_tolerance", 0.0), "goal_pose.position_tolerance",
                                 low=0.0, what=" of meters"),
        orientation_tolerance=_real(goal_pose.get("orientation_tolerance", 0.0), "goal_pose.orientation_tolerance",
                                    low=0.0, what=" of radians"),
    )


class PlanCalls:
    """The planning call of :class:`~sublevel_client.Client` (a mixin: it relies on the client's
    ``_call`` and, from the robot calls, ``_joints``)."""

    def _plan_request(
        self,
        robot: Optional[str],
        *,
        scene: str = "",
        start: Any = None,
        goal: Any = None,
        goal_joints: Optional[Mapping[str, Any]] = None,
        goal_pose: Optional[Mapping[str, Any]] = None,
        motion_plan_request: Any = None,
        joint_names: Optional[Sequence[str]] = None,
        base: Any = None,
        timeout: float = 1.0,
        seed: Optional[int] = None,
        range: Optional[float] = None,  # noqa: A002 (the setting's name)
        padding: float = 0.0,
        simplify: bool = True,
        smoothing_passes: int = 0,
        resolution: Optional[float] = None,
        goal_bias: Optional[float] = None,
        tolerance: Optional[float] = None,
        max_goals: Optional[int] = None,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
        start_state_max_bounds_error: Optional[float] = None,
        planning_joints: Optional[Sequence[str]] = None,
        trajectory: Optional[pb.TrajectorySettings] = None,
        fidelity: Optional[str] = None,
        sphere_tolerance: float = 0.0,
    ) -> pb.PlanRequest:
        """The ``PlanRequest`` of :meth:`plan` (same arguments), validated here."""
        if robot is not None and not isinstance(robot, str):
            raise ValueError(f"`robot`: expected a robot id string or None, got {robot!r}")
        if not isinstance(scene, str):
            raise ValueError(f"`scene`: expected a scene id string, got {scene!r}")
        if not robot and not scene:
            raise ValueError("`robot`: required without `scene`: name a robot, or a scene holding one")
        req = pb.PlanRequest(
            robot_id=robot or "",
            scene_id=scene,
            settings=_plan_settings(timeout, seed, range, padding, simplify, smoothing_passes, resolution, goal_bias,
                                    tolerance, max_goals, start_state_max_bounds_error),
            attached=_attached_pb(attached),
            link_padding=_link_padding(link_padding),
        )
        if planning_joints is not None:
            if isinstance(planning_joints, str) or not all(isinstance(n, str) for n in planning_joints):
                raise ValueError(f"`planning_joints`: expected a sequence of joint names, got {planning_joints!r}")
            req.planning_joints.extend(planning_joints)
        if trajectory is not None:
            req.trajectory.CopyFrom(trajectory)
        level = _fidelity_pb(fidelity, sphere_tolerance)
        if level is not None:
            req.fidelity.CopyFrom(level)
        if base is not None:
            req.base.CopyFrom(_pose_pb(base, "base"))
        given = {"start": start, "goal": goal, "goal_joints": goal_joints, "goal_pose": goal_pose,
                 "joint_names": joint_names}
        if motion_plan_request is not None:
            typed = [k for k, v in given.items() if v is not None]
            if typed:
                raise ValueError(
                    f"`motion_plan_request`: give the start and the goal either in it or in the typed arguments, "
                    f"not both (`{typed[0]}` given too)"
                )
            kind, text = _motion_plan_request(motion_plan_request)
            if kind == "json":
                req.motion_plan_request_json = text
            else:
                req.motion_plan_request_yaml = text
            return req
        goals = [k for k in ("goal", "goal_joints", "goal_pose") if given[k] is not None]
        if not goals:
            raise ValueError("`goal`: required: `goal`, `goal_joints`, `goal_pose` or `motion_plan_request`")
        if len(goals) > 1:
            raise ValueError(f"`{goals[1]}`: give one kind of goal (`{goals[0]}` given too)")
        if start is not None or goal is not None:
            robot_id, names, n, what = self._joints(robot, scene, joint_names)
            if start is not None:
                q0 = _configurations(start, n, "start", what)
                if q0.shape[0] != 1:
                    raise ValueError(f"`start`: expected one configuration, shape ({n},), got shape {np.shape(start)}")
                req.start.CopyFrom(_configuration_columns(q0, names))
            if goal is not None:
                req.goal_configurations.CopyFrom(_configuration_columns(_configurations(goal, n, "goal", what), names))
        elif joint_names is not None:
            raise ValueError("`joint_names`: names the columns of `start` and `goal`, and neither is given")
        if goal_joints is not None:
            req.goal_joint_constraints.extend(_joint_constraints(goal_joints))
        if goal_pose is not None:
            req.goal_pose.CopyFrom(_pose_goal(goal_pose))
        return req

    def plan(
        self,
        robot: Optional[str],
        *,
        scene: str = "",
        start: Any = None,
        goal: Any = None,
        goal_joints: Optional[Mapping[str, Any]] = None,
        goal_pose: Optional[Mapping[str, Any]] = None,
        motion_plan_request: Any = None,
        joint_names: Optional[Sequence[str]] = None,
        base: Any = None,
        timeout: float = 1.0,
        seed: Optional[int] = None,
        range: Optional[float] = None,  # noqa: A002 (the setting's name)
        padding: float = 0.0,
        simplify: bool = True,
        smoothing_passes: int = 0,
        resolution: Optional[float] = None,
        goal_bias: Optional[float] = None,
        tolerance: Optional[float] = None,
        max_goals: Optional[int] = None,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
        start_state_max_bounds_error: Optional[float] = None,
        planning_joints: Optional[Sequence[str]] = None,
        trajectory: bool = False,
        sample_dt: Optional[float] = None,
        velocity_scaling: Optional[float] = None,
        acceleration_scaling: Optional[float] = None,
        max_deviation: Optional[float] = None,
        max_velocity: Optional[Mapping[str, float]] = None,
        max_acceleration: Optional[Mapping[str, float]] = None,
        joint_limits: Any = None,
        grpc_timeout: Optional[float] = None,
        fidelity: Optional[str] = None,
        sphere_tolerance: float = 0.0,
    ) -> PlanResult:
        """Plans a path of a stored robot among a scene in one call (``Plan``; docs/planning.md):
        RRT-Connect from the start to the goal, the path simplified, then every edge proven free by
        conservative advancement (an edge that is not is split or re-planned). A solved plan's path
        needs no further check at any sampling resolution.

        The start and the goal are given either by ``start`` and one kind of goal (``goal``,
        ``goal_joints`` or ``goal_pose``), or by ``motion_plan_request`` alone.

        Args:
            robot: the robot's id (:meth:`upload_robot`); None (or ""): the robot of ``scene``
                (:meth:`set_scene_robot`) with its base unless ``base`` is given, its attached
                objects plus ``attached`` and its link padding.
            scene: the world (e.g. :meth:`import_scene`'s scene, its allowed-collision matrix
                applying); empty: no obstacles (self-collision only).
            start: the start configuration, array-like of shape (n,) (radians for revolute and
                continuous joints, meters for prismatic ones); None: the scene's joint positions.
            goal: goal configurations, shape (n,) or (G, n): the path ends at one of them.
            goal_joints: a goal region, ``{joint: position}`` or ``{joint: (position,
                tolerance_below, tolerance_above)}`` (as MoveIt's joint constraints; tolerances
                >= 0); joints not named end at the start's values.
            goal_pose: a link pose goal, a dict ``{"link": name, "pose": pose,
                "position_tolerance": meters, "orientation_tolerance": radians}``: the pose of the
                link frame in the world (a :class:`Pose`, a 7-vector ``[w, x, y, z, tx, ty, tz]``
                or a 4x4 matrix); tolerances 0 (the default): 1 mm and 0.01 rad; an orientation
                tolerance >= pi: any orientation. Goal configurations are found by inverse
                kinematics.
            motion_plan_request: a MoveIt ``MotionPlanRequest`` (its start state, whose names must
                be joints of the robot, and its goal constraints' joint constraints, as
                MotionBenchMaker's request files hold them; other constraints are refused): YAML or JSON text (JSON when it starts with ``{``), bytes, a mapping (sent
                as JSON), or a path to such a file (``os.PathLike``, or a one-line ``str`` naming
                an existing file).
            joint_names: the n joints of ``start``'s and ``goal``'s columns, each once; None:
                every joint of the robot in :attr:`RobotInfo.joint_names` order (with ``robot``
                None: of the scene's robot, one GetScene). Joints not named take the scene's joint
                positions, else 0.
            base: the pose of the robot's root link in the scene (as ``goal_pose``'s pose); None:
                the scene robot's base, else the identity.
            timeout: the whole plan's time on the server, seconds (> 0; at most 3600), counted
                from the request's arrival: the wait for a planning slot, the goals, the search,
                the simplification and the certification.
            seed: the sampler's and the simplification's seed (>= 0): the same request gives the
                same path; None: 1.
            range: the longest extension step (joint-space distance, > 0); None: 1.0.
            padding: meters (in [0, 1]) every robot geometry keeps clear, on top of the link
                padding.
            simplify: whether the path is simplified (shortcuts, redundant waypoints dropped).
            smoothing_passes: corner-cutting passes after the shortcuts (0 to 8).
            resolution: configurations per unit of joint distance on the search's edges (in
                (0, 1000]); None: 32.
            goal_bias: the chance that a round of the search draws a goal, in [0, 1); None: 0.05.
            tolerance: the edge certificates' contact tolerance, meters (in (0, 0.1]); None: 1 mm.
            max_goals: most goal configurations the goal tree is rooted at (1 to 64; the first
                free ones of those given are kept); None: 8.
            attached, link_padding: as in :meth:`check_configurations`.
            start_state_max_bounds_error: how far a start value may lie outside its joint's limits
                (radians or meters, in [0, 1]) and still be planned from, moved onto the limit and
                said in :attr:`PlanResult.warnings` (MoveIt's ``FixStartStateBounds``); None: 0.05.
            planning_joints: the joints the plan moves (MoveIt's planning group), the others held at
                the start's values on every waypoint; None: the joints the goal names
                (``goal_joints``, the request's goal constraints, ``joint_names`` of ``goal``), or
                every joint when it names none (a goal of every joint, ``goal_pose``).
            trajectory: whether the answer holds the path timed too (:attr:`PlanResult.trajectory`,
                docs/planning.md "Timed trajectories"): corners blended by arcs proven free, then
                time-optimal within the joints' velocity and acceleration limits, at rest at both
                ends. The settings below apply only with it.
            sample_dt: seconds between the trajectory's points (> 0); None: 0.01.
            velocity_scaling, acceleration_scaling: factors in (0, 1] on the limits (MoveIt's
                ``max_velocity_scaling_factor`` / ``max_acceleration_scaling_factor``); None: the
                request's MotionPlanRequest's, else ``joint_limits``' defaults, else 1.
            max_deviation: most joint-space distance a blended corner passes from its waypoint
                (>= 0; 0 stops at every waypoint); None: 0.1.
            max_velocity, max_acceleration: limits by joint name (> 0), over the others.
            joint_limits: a MoveIt ``joint_limits.yaml`` (text, or a path as ``os.PathLike`` or a
                one-line ``str`` naming a file): its limits where its ``has_..._limits`` flags are
                true. Joints with no limit anywhere (nor a URDF ``<limit velocity>``) take 1 per
                second and 1 per second squared, said in :attr:`PlanResult.warnings`.
            fidelity, sphere_tolerance: the level of the search's checks, as in
                :meth:`check_configurations` (None: "mesh"): a conservative level searches among
                links inflated by its bodies; the path's edges are still certified on the meshes.
            grpc_timeout: the call's gRPC deadline, seconds; None: ``timeout`` plus
                :data:`PLAN_DEADLINE_MARGIN` (5 s), so that the server answers ``timed_out``
                itself. A shorter deadline also shortens the plan.

        Returns :class:`PlanResult`: its ``status`` (``"solved"``, ``"timed_out"``,
        ``"start_in_collision"``, ``"goal_in_collision"``, ``"goal_unreachable"``,
        ``"cancelled"``), the path of shape (W, n) in :attr:`PlanResult.joint_names` order, its
        length and certificate, and the time of each stage. A colliding start or goal, an
        unreachable pose and a timeout are statuses, not errors.

        Raises ValueError naming the argument when one is malformed (``start`` or ``goal`` of the
        wrong length or not finite, no goal or two kinds of goal, ``motion_plan_request`` with
        typed ends, a setting out of its range; nothing is sent), and SublevelError for the
        server's refusals: NOT_FOUND for an unknown robot or scene, INVALID_ARGUMENT naming the
        field (``start.values[1]`` for a value farther than ``start_state_max_bounds_error``
        outside its joint limits,
        ``goal_configurations.joint_names[0]`` for an unknown joint, ``goal_pose.link`` for a link
        the robot lacks, ``goal_joint_constraints[0].joint_name``,
        ``motion_plan_request_yaml.start_state[3]``), DEADLINE_EXCEEDED when ``grpc_timeout``
        passes before the answer.
        """
        req = self._plan_request(
            robot, scene=scene, start=start, goal=goal, goal_joints=goal_joints, goal_pose=goal_pose,
            motion_plan_request=motion_plan_request, joint_names=joint_names, base=base, timeout=timeout, seed=seed,
            range=range, padding=padding, simplify=simplify, smoothing_passes=smoothing_passes,
            resolution=resolution, goal_bias=goal_bias, tolerance=tolerance, max_goals=max_goals, attached=attached,
            link_padding=link_padding, start_state_max_bounds_error=start_state_max_bounds_error,
            planning_joints=planning_joints,
            trajectory=_trajectory_settings(
                sample_dt, velocity_scaling, acceleration_scaling, max_deviation, max_velocity, max_acceleration,
                joint_limits,
            ) if trajectory else None,
            fidelity=fidelity, sphere_tolerance=sphere_tolerance,
        )
        if grpc_timeout is None:
            deadline = req.settings.timeout + PLAN_DEADLINE_MARGIN
        else:
            deadline = _real(grpc_timeout, "grpc_timeout", low=0.0, low_open=True, what=" of seconds")
        return PlanResult.from_proto(self._call("Plan", req, timeout=deadline))

    def time_trajectory(
        self,
        robot: Optional[str],
        path: Any,
        *,
        scene: str = "",
        joint_names: Optional[Sequence[str]] = None,
        base: Any = None,
        padding: float = 0.0,
        tolerance: Optional[float] = None,
        attached: Optional[Sequence[dict]] = None,
        link_padding: Optional[Mapping[str, float]] = None,
        sample_dt: Optional[float] = None,
        velocity_scaling: Optional[float] = None,
        acceleration_scaling: Optional[float] = None,
        max_deviation: Optional[float] = None,
        max_velocity: Optional[Mapping[str, float]] = None,
        max_acceleration: Optional[Mapping[str, float]] = None,
        joint_limits: Any = None,
        grpc_timeout: Optional[float] = None,
    ) -> JointTrajectory:
        """Times a path from any planner (OMPL, MoveIt, a teach pendant) among a scene
        (``TimeTrajectory``; docs/planning.md, "Timed trajectories"): every edge proven free by
        conservative advancement, the corners blended by arcs proven free, then timed within the
        joints' velocity and acceleration limits, at rest at both ends.

        Args:
            robot, scene, joint_names, base, attached, link_padding: as in :meth:`plan`.
            path: the waypoints, shape (W, n) in ``joint_names`` order (W >= 2, at least two
                distinct; consecutive repeats are dropped).
            padding: meters (in [0, 1]) every robot geometry keeps clear along the path.
            tolerance: the certificates' contact tolerance, meters (in (0, 0.1]); None: 1 mm.
            sample_dt, velocity_scaling, acceleration_scaling, max_deviation, max_velocity,
                max_acceleration, joint_limits: as in :meth:`plan` with ``trajectory=True``.
            grpc_timeout: the call's gRPC deadline, seconds; None: none (the server allows 60 s).

        Returns :class:`JointTrajectory` (``certified`` true), its ``warnings`` saying which
        limits took defaults and what was skipped.

        Raises ValueError naming the argument when one is malformed (nothing is sent), and
        SublevelError: INVALID_ARGUMENT naming ``path`` and its first edge that is not free (with
        the colliding pair), ``path.values[k]`` for a value outside its joint's limits,
        ``trajectory.FIELD`` for a bad setting; NOT_FOUND for an unknown robot or scene.
        """
        robot_id, names, n, what = self._joints(robot, scene, joint_names)
        rows = _configurations(path, n, "path", what)
        req = pb.TimeTrajectoryRequest(
            robot_id=robot_id,
            scene_id=scene,
            path=_configuration_columns(rows, names),
            trajectory=_trajectory_settings(sample_dt, velocity_scaling, acceleration_scaling, max_deviation,
                                            max_velocity, max_acceleration, joint_limits),
            padding=_real(padding, "padding", low=0.0, high=1.0, what=" of meters"),
            attached=_attached_pb(attached),
            link_padding=_link_padding(link_padding),
        )
        if tolerance is not None:
            req.tolerance = _real(tolerance, "tolerance", low=0.0, low_open=True, high=0.1, what=" of meters")
        if base is not None:
            req.base.CopyFrom(_pose_pb(base, "base"))
        deadline = None if grpc_timeout is None else _real(
            grpc_timeout, "grpc_timeout", low=0.0, low_open=True, what=" of seconds")
        m = self._call("TimeTrajectory", req, timeout=deadline)
        out = JointTrajectory.from_proto(m.trajectory)
        out.warnings = list(m.warnings)
        return out
