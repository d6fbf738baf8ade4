"""Rigid-body motions of scene instances (``Client.check_instance_motions``) against closed forms."""

from __future__ import annotations

import math

import grpc
import numpy as np
import pytest

from sublevel_client import InstanceMotionColumns, SublevelError

TOLERANCE = 1e-4


@pytest.fixture(scope="module")
def balls(client):
    """A scene with balls r = 0.5 at the origin and r = 0.3 at (3, 0, 0): their instance ids."""
    scene = client.create_scene("instance-motions")
    big = client.add_instance(scene, client.upload_primitive("sphere", radius=0.5), [1, 0, 0, 0, 0, 0, 0])
    small = client.add_instance(scene, client.upload_primitive("sphere", radius=0.3), [1, 0, 0, 0, 3, 0, 0])
    return scene, big, small


def test_a_ball_moving_into_a_ball_stops_at_the_closed_form(client, balls):
    """Motion 0 moves the big ball 4 m along +x into the small one: contact when the centres are
    0.8 apart, t* = 2.2 / 4, reported no later and at most tolerance (with the exactness slack of
    a quarter of it) over the 4 m closing speed earlier. Motion 1 turns it half a turn about z
    while it moves 4 m along -x, away from the small ball: free."""
    scene, big, small = balls
    half_turn = [0.0, 0.0, 0.0, 1.0]
    start = np.array([[1, 0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 0, 0]], dtype=float)
    end = np.array([[1, 0, 0, 0, 4, 0, 0], half_turn + [-4, 0, 0]], dtype=float)
    m = client.check_instance_motions(scene, [big, big], start, end, tolerance=TOLERANCE)
    assert isinstance(m, InstanceMotionColumns) and len(m) == 2
    np.testing.assert_array_equal(m.valid, [False, True])
    assert m.decided.all() and (m.steps >= 1).all()
    t_star = 2.2 / 4.0
    assert m.contact_t[0] <= t_star + 1e-12
    assert t_star - m.contact_t[0] <= 1.25 * TOLERANCE / 4.0 + 1e-12, m.contact_t[0]
    np.testing.assert_allclose(m.contact_pose[0], [1, 0, 0, 0, 4 * m.contact_t[0], 0, 0], atol=1e-12)
    assert m.other == [small, ""]
    assert math.isnan(m.contact_t[1]) and np.isnan(m.contact_pose[1]).all()


def test_padding_brings_the_contact_forward_and_bad_input_is_refused(client, balls):
    """With 0.2 m of padding the contact comes at centre distance 1.0, t* = 2.0 / 4; one motion
    may be given as (7,) arrays. Malformed arguments raise ValueError before anything is sent; an
    unknown instance is the server's NOT_FOUND naming its entry."""
    scene, big, small = balls
    m = client.check_instance_motions(
        scene, big, [1, 0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 4, 0, 0], padding=0.2, tolerance=TOLERANCE
    )
    assert 0.5 - 1.25 * TOLERANCE / 4.0 - 1e-12 <= m.contact_t[0] <= 0.5 + 1e-12, m.contact_t[0]
    with pytest.raises(ValueError, match="start_poses"):
        client.check_instance_motions(scene, [big], np.zeros((1, 6)), np.zeros((1, 7)))
    with pytest.raises(ValueError, match="tolerance"):
        client.check_instance_motions(scene, big, [1, 0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 1, 0, 0], tolerance=0.0)
    rest = np.tile([1.0, 0, 0, 0, 0, 0, 0], (2, 1))
    with pytest.raises(SublevelError) as e:
        client.check_instance_motions(scene, [big, "i-0000000000000000"], rest, rest)
    assert e.value.code == grpc.StatusCode.NOT_FOUND and "instance_ids[1]" in str(e.value)
