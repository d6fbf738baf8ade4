"""Unary calls against a real server, checked against closed forms for spheres."""

import json
import math

import grpc
import numpy as np
import pytest

from sublevel_client import (
    CollideAnswer,
    DistanceAnswer,
    GrowthAnswer,
    Pose,
    Query,
    SublevelError,
    quat_from_axis_angle,
    quat_to_matrix,
    sphere_body,
)

R1, R2 = 0.5, 0.3


@pytest.fixture(scope="module")
def spheres(client):
    """Two uploaded balls (radii R1, R2 about their body origin) in a fresh scene."""
    b1 = client.upload_body("ball r=0.5", json.dumps(sphere_body(R1)))  # JSON text
    b2 = client.upload_body("ball r=0.3", sphere_body(R2))  # dict
    scene = client.create_scene("two balls")
    a = client.add_instance(scene, b1, Pose())
    b = client.add_instance(scene, b2, [1, 0, 0, 0, 2.0, 0, 0])
    return scene, a, b, b1, b2


def expected_distance(c1, c2, r1=R1, r2=R2):
    d = np.linalg.norm(c2 - c1)
    n = (c2 - c1) / d
    return d - r1 - r2, c1 + r1 * n, c2 - r2 * n, n


CONFIGS = [
    # (center of A, rotation of A, center of B), centers in meters.
    (np.array([0.0, 0.0, 0.0]), (1.0, 0.0, 0.0, 0.0), np.array([2.0, 0.0, 0.0])),
    (np.array([0.3, -1.2, 0.7]), quat_from_axis_angle((1, 2, 3), 0.8), np.array([-1.1, 0.4, 2.5])),
    (np.array([5.0, 5.0, -5.0]), quat_from_axis_angle((0, 0, 1), 2.5), np.array([5.0, 5.81, -5.0])),
]


@pytest.mark.parametrize("c1,q1,c2", CONFIGS)
def test_distance_of_two_spheres_is_closed_form(client, spheres, c1, q1, c2):
    scene, a, b, _, _ = spheres
    assert client.set_poses(scene, {a: Pose(quat=q1, t=c1), b: np.concatenate([[1, 0, 0, 0], c2])}) == 2
    ans = client.distance(scene, a, b, with_gradient=True)
    assert isinstance(ans, DistanceAnswer)
    dist, wa, wb, n = expected_distance(c1, c2)
    assert abs(ans.distance - dist) < 1e-8
    assert ans.witness_a.shape == ans.witness_b.shape == ans.normal.shape == (3,)
    np.testing.assert_allclose(ans.witness_a, wa, atol=1e-7)
    np.testing.assert_allclose(ans.witness_b, wb, atol=1e-7)
    # Witnesses on the spheres, and the normal from A to B.
    assert abs(np.linalg.norm(ans.witness_a - c1) - R1) < 1e-8
    assert abs(np.linalg.norm(ans.witness_b - c2) - R2) < 1e-8
    np.testing.assert_allclose(ans.normal, n, atol=1e-7)
    assert not ans.overlapping and ans.converged and ans.source == "NEWTON" and not ans.lower_bound
    assert ans.kkt_residual < 1e-6 and ans.iterations >= 0
    # Gradients as twists (v, w) about the world origin: a ball moves with its center c, so
    # d dist / d v_A = −n, d dist / d w_A = −(c_A × n), and the opposite signs for B.
    assert ans.gradient_a.shape == ans.gradient_b.shape == (6,)
    np.testing.assert_allclose(ans.gradient_a, np.concatenate([-n, -np.cross(c1, n)]), atol=1e-6)
    np.testing.assert_allclose(ans.gradient_b, np.concatenate([n, np.cross(c2, n)]), atol=1e-6)


def test_body_frame_center_and_rotation_move_the_sphere(client):
    """A ball centered at c_body in its body frame, posed by (R, t), sits at R c_body + t."""
    cb = np.array([0.2, -0.1, 0.4])
    b1 = client.upload_body("offset ball", sphere_body(R1, center=cb))
    b2 = client.upload_body("ball", sphere_body(R2))
    scene = client.create_scene("offset")
    q = quat_from_axis_angle((0.3, -1.0, 0.5), 1.1)
    t = np.array([0.5, 0.2, -0.3])
    a = client.add_instance(scene, b1, Pose(quat=q, t=t).matrix())  # a 4x4 matrix
    c2 = np.array([1.9, 1.0, 0.4])
    b = client.add_instance(scene, b2, Pose(t=c2))
    c1 = quat_to_matrix(q) @ cb + t
    ans = client.distance(scene, a, b)
    dist, wa, wb, _ = expected_distance(c1, c2)
    assert abs(ans.distance - dist) < 1e-8
    np.testing.assert_allclose(ans.witness_a, wa, atol=1e-7)
    np.testing.assert_allclose(ans.witness_b, wb, atol=1e-7)


@pytest.mark.parametrize("c1,q1,c2", CONFIGS)
def test_growth_of_two_spheres_is_closed_form(client, spheres, c1, q1, c2):
    scene, a, b, _, _ = spheres
    client.set_poses(scene, {a: Pose(quat=q1, t=c1), b: Pose(t=c2)})
    # d(p1 || p2) = min ‖(x − c1)/r1‖² over the ball B2: at the point of B2 nearest c1.
    g = client.growth(scene, a, b)
    assert isinstance(g, GrowthAnswer)
    d = np.linalg.norm(c1 - c2)
    assert abs(g.value - (d - R2) ** 2 / R1**2) < 1e-8 * max(1.0, g.value)
    np.testing.assert_allclose(g.minimizer, c2 + R2 * (c1 - c2) / d, atol=1e-7)
    assert g.separated == (g.value > 1.0) and g.converged
    # And the other way round.
    g2 = client.growth(scene, b, a)
    assert abs(g2.value - (d - R1) ** 2 / R2**2) < 1e-8 * max(1.0, g2.value)


def test_overlapping_spheres(client, spheres):
    scene, a, b, _, _ = spheres
    c2 = np.array([0.6, 0.0, 0.0])  # centers 0.6 apart < R1 + R2 = 0.8
    client.set_poses(scene, {a: Pose(), b: Pose(t=c2)})
    ans = client.distance(scene, a, b)
    assert ans.overlapping and ans.distance == 0.0
    g = client.growth(scene, a, b)
    assert abs(g.value - (0.6 - R2) ** 2 / R1**2) < 1e-8 and not g.separated
    # c1 inside B2: the minimum of p1 is 0 at c1.
    client.set_poses(scene, {b: Pose(t=(0.1, 0.0, 0.0))})
    g = client.growth(scene, a, b)
    assert abs(g.value) < 1e-10
    np.testing.assert_allclose(g.minimizer, [0, 0, 0], atol=1e-6)


def test_certified_distance_and_batch(client, spheres):
    scene, a, b, _, _ = spheres
    c2 = np.array([1.5, 0.5, 0.0])
    client.set_poses(scene, {a: Pose(), b: Pose(t=c2)})
    dist = np.linalg.norm(c2) - R1 - R2
    ans = client.distance(scene, a, b, certify=True)
    assert ans.certificate is not None
    assert abs(ans.certificate.bound - dist**2) < 1e-5 and ans.certificate.agrees
    answers = client.batch(scene, [Query.distance(a, b), ("growth", a, b), Query.growth(b, a)])
    assert [type(x) for x in answers] == [DistanceAnswer, GrowthAnswer, GrowthAnswer]
    assert abs(answers[0].distance - dist) < 1e-8
    assert abs(answers[1].value - (np.linalg.norm(c2) - R2) ** 2 / R1**2) < 1e-8
    assert abs(answers[2].value - (np.linalg.norm(c2) - R1) ** 2 / R2**2) < 1e-8
    with pytest.raises(ValueError, match=r"`queries\[0\]\.kind`"):
        client.batch(scene, [Query.collide(a, b, 0.1)])


def test_demo_scene_and_listing(client, demo):
    names = {b.name: b for b in client.list_bodies()}
    assert names["chair_101"].degree == 4 and names["human_10"].degree == 4
    sc = client.get_scene(demo.scene)
    assert sc.name == "demo" and len(sc.instances) == 2
    ans = client.distance(demo.scene, demo.chair, demo.human)
    assert ans.converged and ans.distance > 0


def test_invalid_argument_carries_its_field(client, spheres):
    scene, a, b, _, _ = spheres
    with pytest.raises(SublevelError) as e:
        client.set_poses(scene, {a: Pose(), b: [1.0, 1.0, 0, 0, 0, 0, 0]})  # norm √2
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert e.value.field == "poses[1].pose.rotation"
    assert "unit norm" in e.value.message
    # All or nothing: A's pose did not change either.
    assert isinstance(e.value, Exception) and "INVALID_ARGUMENT" in str(e.value)


def test_not_found_has_no_field(client):
    with pytest.raises(SublevelError) as e:
        client.distance("s-does-not-exist", "i-a", "i-b")
    assert e.value.code == grpc.StatusCode.NOT_FOUND and e.value.field is None


def test_bad_upload_is_invalid_argument(client):
    body = sphere_body(1.0)
    body["degree"] = 3
    with pytest.raises(SublevelError) as e:
        client.upload_body("bad", body)
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
    assert e.value.field is not None and "degree" in e.value.field


def test_client_side_validation_names_the_argument(client, spheres):
    scene, a, b, b1, _ = spheres
    with pytest.raises(ValueError, match=r"`pose`.*shape \(5,\)"):
        client.add_instance(scene, b1, np.zeros(5))
    with pytest.raises(ValueError, match=r"`poses\[" + b + r"\]`.*shape \(3, 3\)"):
        client.set_poses(scene, {b: np.eye(3)})
    with pytest.raises(ValueError, match=r"`body`"):
        client.upload_body("x", "/no/such/file.json")


def test_signed_distance_of_spheres(client, spheres):
    """Penetration depth of two balls = r1 + r2 − ‖c1 − c2‖, along the line of centers."""
    scene, a, b, _, _ = spheres
    c1, c2 = np.array([0.2, -0.1, 0.3]), np.array([0.6, 0.3, 0.1])  # 0.6 m apart < 0.8
    client.set_poses(scene, {a: Pose(quat=quat_from_axis_angle((1, 1, 0), 0.4), t=c1), b: Pose(t=c2)})
    d = np.linalg.norm(c2 - c1)
    n = (c2 - c1) / d
    ans = client.distance(scene, a, b, signed=True, with_gradient=True)
    assert ans.overlapping and ans.distance == 0.0
    assert abs(ans.penetration_depth - (R1 + R2 - d)) < 1e-7
    assert abs(ans.signed_distance - (d - R1 - R2)) < 1e-7
    np.testing.assert_allclose(ans.penetration_normal, n, atol=1e-6)
    # d signed / d pose: the same twists as the distance of separated balls.
    np.testing.assert_allclose(ans.signed_gradient_a, np.concatenate([-n, -np.cross(c1, n)]), atol=1e-5)
    np.testing.assert_allclose(ans.signed_gradient_b, np.concatenate([n, np.cross(c2, n)]), atol=1e-5)
    # Separated: the signed distance is the distance; in a batch and in a planner query too.
    client.set_poses(scene, {b: Pose(t=(2.0, 0.0, 0.0)), a: Pose()})
    (x,) = client.batch(scene, [Query.distance(a, b, signed=True)])
    assert abs(x.signed_distance - (2.0 - R1 - R2)) < 1e-8 and x.penetration_depth == 0.0
    (y,) = client.query(scene, poses={b: Pose(t=(0.5, 0, 0))}, queries=[Query.distance(a, b, signed=True)]).answers
    assert abs(y.signed_distance - (0.5 - R1 - R2)) < 1e-7
    with pytest.raises(ValueError, match=r"`queries\[0\]\.signed`"):
        client.batch(scene, [Query("growth", a, b, signed=True)])


def test_batch_columns_match_closed_forms_and_pairs(client, spheres):
    """Columns both ways: numpy arrays equal to the closed form and to the per-pair answers."""
    scene, a, b, _, _ = spheres
    c1, c2 = np.array([0.1, 0.2, 0.3]), np.array([1.9, -0.4, 0.8])
    client.set_poses(scene, {a: Pose(t=c1), b: Pose(t=c2)})
    cols = client.batch_columns(scene, "distance", [a, b, a], [b, a, b])
    assert cols.kind == "distance" and len(cols) == 3
    assert cols.point_a.shape == cols.point_b.shape == (3, 3)
    dist, wa, wb, _ = expected_distance(c1, c2)
    np.testing.assert_allclose(cols.value, [dist, dist, dist], atol=1e-8)
    np.testing.assert_allclose(cols.point_a[0], wa, atol=1e-7)
    np.testing.assert_allclose(cols.point_b[0], wb, atol=1e-7)
    np.testing.assert_allclose(cols.point_a[1], wb, atol=1e-7)  # (b, a): the witness on b first
    assert cols.converged.all() and not cols.overlapping.any() and not cols.lower_bound.any()
    per_pair = client.batch(scene, [Query.distance(a, b)])
    assert abs(per_pair[0].distance - cols.value[0]) < 1e-12
    # Collide far beyond the margin: decided by the bounding spheres, points NaN.
    far = client.batch_columns(scene, "collide", [a], [b], margin=0.01)
    assert far.decided_by_bounds.tolist() == [True] and not far.overlapping[0]
    assert np.isnan(far.point_a).all() and 0.01 < far.value[0] <= dist + 1e-9


def test_batch_columns_errors_name_the_field(client, spheres):
    scene, a, b, _, _ = spheres
    with pytest.raises(SublevelError) as e:
        client.batch_columns(scene, "collide", [a], [b], margin=-1.0)
    assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT and e.value.field == "columns.margin"
    with pytest.raises(SublevelError) as e:
        client.batch_columns(scene, "distance", [a], ["i-nope"])
    assert e.value.code == grpc.StatusCode.NOT_FOUND
    with pytest.raises(ValueError):
        client.batch_columns(scene, "distance", [a, b], [b])
