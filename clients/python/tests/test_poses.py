"""Pose conversions against independent numpy references (no server needed)."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from sublevel_client import Pose, as_pose, matrix_to_quat, quat_from_axis_angle, quat_multiply, quat_to_matrix

RNG = np.random.default_rng(7)


def rodrigues(axis, angle):
    """R = I + sin θ K + (1 − cos θ) K², K the cross-product matrix of the unit axis."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def random_axis_angles(n):
    for _ in range(n):
        yield RNG.normal(size=3), RNG.uniform(-math.pi, math.pi)
    # The branches of Shepperd's method: half turns about each axis and near-half turns.
    for axis in np.eye(3):
        yield axis, math.pi
        yield axis, math.pi - 1e-7
    yield np.array([1.0, 1.0, 0.0]), math.pi
    yield np.array([0.0, 1.0, 1.0]), -math.pi + 1e-3
    yield np.array([1.0, 0.0, 0.0]), 0.0


@pytest.mark.parametrize("axis,angle", list(random_axis_angles(40)))
def test_quaternion_matrix_against_rodrigues(axis, angle):
    q = quat_from_axis_angle(axis, angle)
    R = rodrigues(axis, angle)
    np.testing.assert_allclose(quat_to_matrix(q), R, atol=1e-12)
    q2 = np.array(matrix_to_quat(R))
    assert q2[0] >= 0.0
    assert abs(np.linalg.norm(q2) - 1.0) < 1e-14
    # q and −q are the same rotation.
    assert min(np.linalg.norm(q2 - q), np.linalg.norm(q2 + q)) < 1e-7
    np.testing.assert_allclose(quat_to_matrix(q2), R, atol=1e-12)


def test_rotation_of_vectors_matches_hamilton_product():
    for _ in range(20):
        q = np.array(quat_from_axis_angle(RNG.normal(size=3), RNG.uniform(0, 6)))
        v = RNG.normal(size=3)
        # q v q*, with v as the pure quaternion (0, v).
        qv = quat_multiply(quat_multiply(q, (0.0, *v)), (q[0], -q[1], -q[2], -q[3]))
        np.testing.assert_allclose(qv[1:], quat_to_matrix(q) @ v, atol=1e-12)
        assert abs(qv[0]) < 1e-12


def test_pose_forms_agree_and_compose_like_matrices():
    for _ in range(10):
        q = quat_from_axis_angle(RNG.normal(size=3), RNG.uniform(-3, 3))
        t = RNG.normal(size=3)
        p = Pose(quat=q, t=t)
        M = np.eye(4)
        M[:3, :3] = quat_to_matrix(q)
        M[:3, 3] = t
        np.testing.assert_allclose(p.matrix(), M, atol=1e-15)
        from_m = as_pose(M)
        from_v = as_pose(np.concatenate([q, t]))
        from_list = as_pose(list(q) + list(t))
        for other in (from_m, from_v, from_list):
            np.testing.assert_allclose(other.matrix(), M, atol=1e-12)
        x = RNG.normal(size=(5, 3))
        np.testing.assert_allclose(p.apply(x), (M[:3, :3] @ x.T).T + t, atol=1e-12)
        q2 = quat_from_axis_angle(RNG.normal(size=3), RNG.uniform(-3, 3))
        p2 = Pose(quat=q2, t=RNG.normal(size=3))
        np.testing.assert_allclose((p @ p2).matrix(), p.matrix() @ p2.matrix(), atol=1e-12)
        np.testing.assert_allclose(p.inverse().matrix(), np.linalg.inv(M), atol=1e-12)
    assert as_pose(None) == Pose()
    np.testing.assert_array_equal(Pose().vector(), [1, 0, 0, 0, 0, 0, 0])


@pytest.mark.parametrize(
    "bad,pattern",
    [
        (np.zeros(5), r"`pose`.*shape \(5,\)"),
        (np.eye(3), r"`pose`.*shape \(3, 3\)"),
        ("not a pose", r"`pose`"),
        (np.diag([1.0, 1.0, 2.0, 1.0]), r"`pose`: not a rotation matrix"),
        (np.diag([1.0, 1.0, -1.0, 1.0]), r"`pose`: not a rotation matrix"),
        (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]]), r"`pose`: the last row"),
        ([1, 0, 0, 0, 0, float("nan"), 0], r"`pose`: expected finite"),
    ],
)
def test_bad_poses_raise_value_error_naming_the_argument(bad, pattern):
    with pytest.raises(ValueError, match=pattern):
        as_pose(bad, "pose")


def test_pose_fields_are_validated():
    with pytest.raises(ValueError, match=r"`quat`.*shape \(3,\)"):
        Pose(quat=(1, 0, 0))
    with pytest.raises(ValueError, match=r"`t`.*shape \(2,\)"):
        Pose(t=(1, 2))


def test_generated_stubs_match_the_proto_on_disk():
    """The stubs were generated at build time from proto/: every rpc of the file is a method."""
    from sublevel_client._pb.sublevel.v1 import sublevel_pb2, sublevel_pb2_grpc

    proto = Path(__file__).resolve().parents[3] / "proto" / "sublevel" / "v1" / "sublevel.proto"
    if not proto.is_file():
        pytest.skip("not in the repository checkout")
    rpcs = re.findall(r"^\s*rpc\s+(\w+)\s*\(", proto.read_text(), re.M)
    service = sublevel_pb2.DESCRIPTOR.services_by_name["Sublevel"]
    assert [m.name for m in service.methods] == rpcs
    assert hasattr(sublevel_pb2_grpc, "SublevelStub")
    assert sublevel_pb2.DESCRIPTOR.package == "sublevel.v1"
