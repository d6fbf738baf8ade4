"""Types of an imported MoveIt planning scene: its instances, the shapes it skipped, the meshes
being fitted, and its allowed-collision matrix. Units: meters; poses as :class:`~sublevel_client.Pose`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

import numpy as np

from .poses import Pose
from ._convert import _pose


@dataclass
class AllowedCollisionMatrix:
    """A MoveIt allowed-collision matrix: which pairs of names (robot links, object ids) may touch.

    Attributes:
        names: the names of the rows and columns.
        matrix: ``(n, n)`` bool array; ``matrix[i, j]``: contacts of ``names[i]`` and ``names[j]``
            are allowed.
        defaults: names with a default entry, and whether their contacts are all allowed.
    """

    names: List[str]
    matrix: np.ndarray
    defaults: Dict[str, bool] = field(default_factory=dict)

    def allowed(self, a: str, b: str) -> bool:
        """Whether contacts between ``a`` and ``b`` are allowed: the matrix entry when both are
        named, else a default entry of either that allows them (MoveIt's rule)."""
        if a in self.names and b in self.names:
            return bool(self.matrix[self.names.index(a), self.names.index(b)])
        return bool(self.defaults.get(a, False) or self.defaults.get(b, False))

    @classmethod
    def from_proto(cls, m) -> "AllowedCollisionMatrix":
        n = len(m.names)
        matrix = np.array([list(r.allowed) for r in m.rows], dtype=bool).reshape(n, n)
        return cls(names=list(m.names), matrix=matrix, defaults=dict(zip(m.default_names, m.default_allowed)))


@dataclass
class ImportedInstance:
    """One imported shape of a planning scene: an instance of a primitive body.

    Attributes:
        name: the collision object's id, with ``#k`` when the object has several shapes.
        object_id, shape_index: the object and the shape's index in it (primitives, then meshes,
            then planes).
        instance_id, body_id: the new instance and its (shared) primitive body.
        kind: ``"box"``, ``"sphere"``, ``"cylinder"`` or ``"halfspace"`` (a plane).
        pose: its pose in the scene; frame_id: the object's header frame.
        note: how the shape was approximated (a cone by its cylinder), else empty.
    """

    name: str
    object_id: str
    shape_index: int
    instance_id: str
    body_id: str
    kind: str
    pose: Pose
    frame_id: str
    note: str

    @classmethod
    def from_proto(cls, m) -> "ImportedInstance":
        return cls(
            name=m.name,
            object_id=m.object_id,
            shape_index=m.shape_index,
            instance_id=m.instance_id,
            body_id=m.body_id,
            kind=m.kind,
            pose=_pose(m.pose, m.HasField("pose")),
            frame_id=m.frame_id,
            note=m.note,
        )


@dataclass
class SkippedShape:
    """A shape of the planning scene that was not imported (a mesh), with its pose and why."""

    object_id: str
    shape_index: int
    kind: str
    pose: Pose
    reason: str

    @classmethod
    def from_proto(cls, m) -> "SkippedShape":
        return cls(
            object_id=m.object_id,
            shape_index=m.shape_index,
            kind=m.kind,
            pose=_pose(m.pose, m.HasField("pose")),
            reason=m.reason,
        )


@dataclass
class ImportedMesh:
    """A mesh of the planning scene being fitted as a compound body (a body containing it, its
    frame the mesh's frame) by its own fit job, which then adds its instance at ``pose``.

    Attributes:
        name: the instance's name (the collision object's id, with ``#k`` when the object has
            several shapes).
        object_id, shape_index: the object and the shape's index in it.
        job_id: the compound fit job (``WatchFitJob`` / ``GetFitJob``).
        pose: the instance's pose in the scene (object pose composed with the mesh pose);
            frame_id: the object's header frame.
        vertices, triangles: the mesh's counts.
        state: the job's final state (``"SUCCEEDED"``, ``"FAILED"``, ``"CANCELLED"``) once waited
            for (``import_scene(wait=True)``), else ``""``.
        body_id: the stored body, once the job succeeded; message, error: the job's final
            message (it says whether the instance was added) and error.
    """

    name: str
    object_id: str
    shape_index: int
    job_id: str
    pose: Pose
    frame_id: str
    vertices: int
    triangles: int
    state: str = ""
    body_id: str = ""
    message: str = ""
    error: str = ""

    @classmethod
    def from_proto(cls, m) -> "ImportedMesh":
        return cls(
            name=m.name,
            object_id=m.object_id,
            shape_index=m.shape_index,
            job_id=m.job_id,
            pose=_pose(m.pose, m.HasField("pose")),
            frame_id=m.frame_id,
            vertices=m.vertices,
            triangles=m.triangles,
        )


@dataclass
class ImportedScene:
    """The answer of ``Client.import_scene``: the new scene, its instances by name, the skipped
    shapes, and the planning scene's allowed-collision matrix and robot state (not stored by the
    server: keep them here).

    Attributes:
        scene_id, name: the new scene.
        instances: the imported shapes, object by object; with ``import_scene(wait=True)`` also
            the meshes' instances once their fits ended (kind ``"mesh"``).
        meshes: the meshes being fitted, one job each (:class:`ImportedMesh`).
        skipped: the shapes not imported (meshes, with ``skip_meshes``).
        objects: collision objects in the planning scene; bodies: primitive bodies stored.
        allowed_collision: the matrix, or None.
        joint_positions: the robot state's joint positions by name (radians or meters).
    """

    scene_id: str
    name: str
    instances: List[ImportedInstance]
    skipped: List[SkippedShape]
    objects: int
    bodies: int
    allowed_collision: Optional[AllowedCollisionMatrix]
    joint_positions: Dict[str, float]
    meshes: List[ImportedMesh] = field(default_factory=list)

    @property
    def ids(self) -> Dict[str, str]:
        """Instance ids by instance name."""
        return {i.name: i.instance_id for i in self.instances}

    @classmethod
    def from_proto(cls, m) -> "ImportedScene":
        return cls(
            scene_id=m.scene_id,
            name=m.name,
            instances=[ImportedInstance.from_proto(i) for i in m.instances],
            skipped=[SkippedShape.from_proto(s) for s in m.skipped],
            objects=m.objects,
            bodies=m.bodies,
            allowed_collision=AllowedCollisionMatrix.from_proto(m.allowed_collision)
            if m.HasField("allowed_collision")
            else None,
            joint_positions={j.name: j.position for j in m.joint_positions},
            meshes=[ImportedMesh.from_proto(x) for x in m.meshes],
        )
