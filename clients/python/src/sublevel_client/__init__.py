"""Python client of the Sublevel gRPC service: real-time collision queries between bodies that are
sublevel sets of sos-convex polynomials.

Units: meters for every length; rotations as unit quaternions ``(w, x, y, z)``; a pose maps body
points to world points, ``x_world = R x_body + t``.

Quickstart::

    from sublevel_client import Client, Pose, Query, sphere_body

    c = Client("127.0.0.1:50051")
    a = c.upload_body("ball", sphere_body(0.5))
    scene = c.create_scene("two balls")
    i = c.add_instance(scene, a, Pose(t=(0, 0, 0)))
    j = c.add_instance(scene, a, [1, 0, 0, 0, 2.0, 0, 0])     # 7-vector w, x, y, z, tx, ty, tz
    print(c.distance(scene, i, j).distance)                  # 1.0 (meters)
    with c.stream(scene) as s:
        print(s.check(poses={j: Pose(t=(1.5, 0, 0))}, queries=[Query.collide(i, j, margin=0.6)]))

The gRPC stubs (``sublevel_client._pb.sublevel.v1.sublevel_pb2`` and ``..._pb2_grpc``) are
generated from the repository's ``proto/`` when the package is built.
"""

from .bodies import ellipsoid_body, sphere_body
from .clouds import CloudBodiesReport, FilterCounts, PointCloudInfo, PointCloudUpdate
from .client import DEFAULT_ADDR, Client, PlannerStream, Query
from .errors import SublevelError
from .poses import Pose, as_pose, matrix_to_quat, quat_from_axis_angle, quat_multiply, quat_to_matrix
from .types import (
    AllowedCollisionMatrix,
    AnswerColumns,
    BodySummary,
    Certificate,
    CollideAnswer,
    ConfigurationColumns,
    DistanceAnswer,
    GrowthAnswer,
    ImportedInstance,
    ImportedMesh,
    ImportedScene,
    Instance,
    InstanceMotionColumns,
    JointTrajectory,
    MotionColumns,
    PlanResult,
    QueryResult,
    RobotInfo,
    Scene,
    SceneCheck,
    SceneRobot,
    ScenePair,
    SceneSummary,
    SkippedShape,
    SolveInfo,
    StateAnswers,
    TreeAnswer,
    UploadedBody,
)

__version__ = "0.1.0"

__all__ = [
    "Client",
    "PlannerStream",
    "Query",
    "DEFAULT_ADDR",
    "SublevelError",
    "Pose",
    "as_pose",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_multiply",
    "quat_from_axis_angle",
    "sphere_body",
    "ellipsoid_body",
    "AllowedCollisionMatrix",
    "AnswerColumns",
    "BodySummary",
    "Certificate",
    "CollideAnswer",
    "ConfigurationColumns",
    "DistanceAnswer",
    "FilterCounts",
    "GrowthAnswer",
    "ImportedInstance",
    "ImportedMesh",
    "ImportedScene",
    "Instance",
    "InstanceMotionColumns",
    "MotionColumns",
    "JointTrajectory",
    "PlanResult",
    "CloudBodiesReport",
    "PointCloudInfo",
    "PointCloudUpdate",
    "QueryResult",
    "RobotInfo",
    "Scene",
    "SceneCheck",
    "SceneRobot",
    "ScenePair",
    "SceneSummary",
    "SkippedShape",
    "SolveInfo",
    "StateAnswers",
    "TreeAnswer",
    "UploadedBody",
]
