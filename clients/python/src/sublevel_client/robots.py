"""The robot calls of :class:`~sublevel_client.Client`: robot fits and uploads, joint
configurations and motions checked (columns in, numpy columns out), and the robot of a scene (its
joint positions, attached objects).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Callable, List, Mapping, Optional, Sequence, Tuple, Union

import grpc

from ._pb.sublevel.v1 import sublevel_pb2 as pb
from .errors import SublevelError
from .types import (
    ConfigurationColumns,
    MotionColumns,
    RobotInfo,
    SceneRobot,
)
from ._requests import (
    _attached_one,
    _attached_pb,
    _configuration_columns,
    _configurations,
    _fidelity_pb,
    _joint_names,
    _joint_positions,
    _link_padding,
    _pose_pb,
    _robot_file,
)


class RobotCalls:
    """The robot calls of :class:`~sublevel_client.Client` (a mixin: it relies on the client's
    ``_call``, ``_wait_job``, ``_robots`` and ``stub``)."""

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
        leaves: bool = False,
        progress: Any = None,
        timeout: Optional[float] = None,
    ) -> RobotInfo:
        """Fits a robot on the server from its URDF (``StartRobotFitJob``) and waits for it, as
        ``sublevel robot fit`` does: URDF primitives stay exact, each link mesh becomes one
        sos-convex body containing it (a compound tree with ``leaves``; cached by content on the
        server, so a re-fit is quick), the SRDF's disabled pairs become the allowed pairs.

        Args:
            urdf: the URDF file. Every mesh its collision elements name is read and sent:
                ``package://NAME/PATH`` from ``DIR/NAME/PATH`` for the first of ``package_dirs``
                that has it (as ROS and pinocchio resolve it), a relative path from the URDF's
                directory.
            srdf: the SRDF file, if any.
            name: the stored robot's name; empty: the URDF's robot name.
            tolerance: with ``leaves``, leaf-excess tolerance of each mesh's fit, meters; 0: 1 %
                of each mesh's bounding-box diagonal.
            max_parts: with ``leaves``, most leaves per link (2..64); 0: 32.
            leaves: also fit each mesh's compound tree (minutes per robot); default one body per
                mesh, what the checks read (seconds).
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
            leaves=bool(leaves),
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
        fidelity: Optional[str] = None,
        sphere_tolerance: float = 0.0,
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
        level = _fidelity_pb(fidelity, sphere_tolerance)
        if level is not None:
            req.fidelity.CopyFrom(level)
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
        resolution: float = 0.0,
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
        if not (float(resolution) >= 0.0) or not math.isfinite(float(resolution)):
            raise ValueError(
                f"`resolution`: expected samples per unit of joint distance >= 0 (0: certified), got {resolution!r}"
            )
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
            resolution=float(resolution),
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
        fidelity: Optional[str] = None,
        sphere_tolerance: float = 0.0,
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
            fidelity: how closely the links are modelled: "mesh" (None: the default; the meshes'
                own verdicts and distances), "bodies" (their sos-convex bodies) or "spheres"
                (their sphere trees cut at ``sphere_tolerance``). Every level's bodies contain the
                meshes, so no level misses a mesh collision; a conservative one may call a
                configuration near contact colliding that the meshes call free, and its distance
                is a lower bound of the meshes'. The ``fidelity`` column says which model each
                verdict rests on.
            sphere_tolerance: meters in [0.01, 1] that the "spheres" level's balls may reach past
                the meshes (0: 0.03).

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
            stop_at_first_collision=stop_at_first_collision, fidelity=fidelity, sphere_tolerance=sphere_tolerance,
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
        resolution: float = 0.0,
    ) -> MotionColumns:
        """Checks straight joint-space motions ``q0[m] -> q1[m]`` (continuous joints the shorter
        way) by conservative advancement: each is proven free, or answered with its first contact
        parameter t* (within ``tolerance``), the configuration and the pair there. No sampling
        resolution to choose — unless ``resolution`` asks for a sampled check instead.

        Args:
            robot, scene, joint_names, base, padding, attached, link_padding: as in
                :meth:`check_configurations` (``robot`` None: the scene's robot).
            q0, q1: start and end configurations, array-like of the same shape, (M, n) or (n,)
                for one motion (radians, meters).
            tolerance: meters (> 0): a distance bound at or below ``padding + tolerance`` is a
                contact.
            max_steps: most advancement steps per motion before it is answered undecided
                (``decided`` false); 0: the server's default (100 000).
            resolution: 0 (the default): certified, as above. > 0: sampled, in samples per unit
                of joint distance (VAMP uses 32): motion m is checked at the ``n = max(1,
                ceil(|q1[m] - q0[m]| * resolution))`` configurations ``q0 + t (q1 - q0)``, ``t = i /
                n``, ``i = 1 .. n`` (``q0`` itself is not checked); ``valid`` then means no sample
                collides, ``decided`` is true, ``contact_t`` is a colliding sample's t (the smallest
                of the first block of samples holding one, not necessarily the first contact),
                ``samples`` the samples checked; ``tolerance`` and ``max_steps`` do not apply. A
                sampled check can miss a collision between its samples; the certified one cannot.
                At most 100 000 samples per motion.

        Returns :class:`MotionColumns` (numpy columns of M rows). Raises ValueError naming the
        argument when ``q0``, ``q1``, ``joint_names``, ``base`` or ``tolerance`` is malformed
        (nothing is sent), and SublevelError for the server's refusals, as
        :meth:`check_configurations`.
        """
        req = self._motions_request(
            robot, q0, q1, scene=scene, joint_names=joint_names, base=base, padding=padding, tolerance=tolerance,
            max_steps=max_steps, attached=attached, link_padding=link_padding, resolution=resolution,
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
