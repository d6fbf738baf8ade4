"""The planner RPCs (Query, QueryStream via the stream helper, CheckScene) on a real server."""

import threading

import grpc
import numpy as np
import pytest

from sublevel_client import CollideAnswer, DistanceAnswer, GrowthAnswer, Pose, Query, SublevelError, sphere_body

R1, R2 = 0.5, 0.3


@pytest.fixture(scope="module")
def balls(client):
    """A scene of two balls whose surfaces are 1 m apart (centers 1.8 m apart on x)."""
    b1 = client.upload_body("ball r=0.5", sphere_body(R1))
    b2 = client.upload_body("ball r=0.3", sphere_body(R2))
    scene = client.create_scene("planner balls")
    a = client.add_instance(scene, b1, Pose())
    b = client.add_instance(scene, b2, Pose(t=(1.8, 0.0, 0.0)))
    return scene, a, b


def test_stream_on_demo_scene_matches_unary_distance(client, restore_demo):
    demo = restore_demo
    xs = np.linspace(0.4, 1.6, 7)  # the chair slides towards the human (at x = 2.92 m)
    q = (0.9238795325112867, 0.0, 0.0, 0.3826834323650898)  # 45° about z
    with client.stream(demo.scene) as s:
        streamed = []
        for x in xs:
            pose = Pose(quat=q, t=(x, 0.1, 0.0))
            (d, g) = s.check(poses={demo.chair: pose}, queries=[Query.distance(demo.chair, demo.human), Query.growth(demo.chair, demo.human)])
            assert isinstance(d, DistanceAnswer) and isinstance(g, GrowthAnswer)
            streamed.append((pose, d, g))
    for k, (pose, d, g) in enumerate(streamed):
        assert d.warm_started == (k > 0), k
        assert g.warm_started == (k > 0), k
        client.set_poses(demo.scene, {demo.chair: pose})
        u = client.distance(demo.scene, demo.chair, demo.human)
        ug = client.growth(demo.scene, demo.chair, demo.human)
        assert not u.warm_started or k > 0
        assert d.converged and u.converged
        assert abs(d.distance - u.distance) < 1e-9, (k, d.distance, u.distance)
        np.testing.assert_allclose(d.witness_a, u.witness_a, atol=1e-6)
        np.testing.assert_allclose(d.witness_b, u.witness_b, atol=1e-6)
        assert abs(g.value - ug.value) < 1e-9 * max(1.0, ug.value)


def test_stream_poses_are_private_to_the_stream(client, balls):
    scene, a, b = balls
    stored = {i.instance_id: i.pose for i in client.get_scene(scene).instances}
    with client.stream(scene) as s:
        (d,) = s.check(poses={b: Pose(t=(3.0, 0, 0))}, queries=[Query.distance(a, b)])
        assert abs(d.distance - (3.0 - R1 - R2)) < 1e-8
        # The view keeps the pose for later requests of the same stream.
        (d,) = s.check(queries=[Query.distance(a, b)])
        assert abs(d.distance - (3.0 - R1 - R2)) < 1e-8
        assert d.warm_started
    # Nothing was written to the store, and a unary call sees the stored pose.
    assert {i.instance_id: i.pose for i in client.get_scene(scene).instances} == stored
    assert abs(client.distance(scene, a, b).distance - (1.8 - R1 - R2)) < 1e-8


@pytest.mark.parametrize("margin,collides", [(0.0, False), (0.5, False), (0.99, False), (1.01, True), (2.0, True)])
def test_collide_with_margin(client, balls, margin, collides):
    scene, a, b = balls  # surfaces 1 m apart
    r = client.query(scene, queries=[Query.collide(a, b, margin)])
    (c,) = r.answers
    assert isinstance(c, CollideAnswer)
    assert c.collides is collides
    assert c.margin == margin
    if not c.decided_by_bounds:
        assert abs(c.distance - 1.0) < 1e-8 and c.solve is not None and c.solve.converged
    else:
        assert c.distance <= 1.0 + 1e-12 and c.solve is None
    assert r.server_seconds >= 0.0
    with client.stream(scene) as s:
        (c2,) = s.check(queries=[("collide", a, b, margin)])
        assert c2.collides is collides


def test_unary_query_with_pose_overrides_writes_nothing(client, balls):
    scene, a, b = balls
    r = client.query(scene, poses={b: Pose(t=(0.7, 0, 0))}, queries=[Query.distance(a, b), Query.collide(a, b, 0.0)])
    d, c = r.answers
    assert d.overlapping and d.distance == 0.0 and c.collides
    assert abs(client.distance(scene, a, b).distance - 1.0) < 1e-8


def test_candidate_states(client, balls):
    scene, a, b = balls
    xs = [3.0, 0.5, 0.95, 1.2, 10.0]  # center of B on x; contact at 0.8
    states = [{b: Pose(t=(x, 0.0, 0.0))} for x in xs]
    queries = [Query.collide(a, b, margin=0.2), Query.distance(a, b)]
    with client.stream(scene) as s:
        out = s.check_states(states=states, queries=queries)
        assert len(out) == len(xs)
        for x, st in zip(xs, out):
            c, d = st.answers
            expected = max(0.0, x - R1 - R2)
            assert abs(d.distance - expected) < 1e-8, x
            assert c.collides == (expected < 0.2), x
            assert st.any_collision == c.collides
        # States are dropped afterwards: the view still has the stored pose.
        (d,) = s.check(queries=[Query.distance(a, b)])
        assert abs(d.distance - 1.0) < 1e-8
    # The same through the unary Query.
    r = client.query(scene, queries=queries, states=states)
    assert [st.any_collision for st in r.states] == [st.any_collision for st in out]
    assert r.answers == []


def test_stream_error_names_the_field_and_ends_the_stream(client, balls):
    scene, a, b = balls
    s = client.stream(scene)
    try:
        # Client-side validation fails before anything is sent: the stream stays usable.
        with pytest.raises(ValueError, match=r"`poses\["):
            s.check(poses={b: np.zeros(3)}, queries=[Query.distance(a, b)])
        assert len(s.check(queries=[Query.distance(a, b)])) == 1
        with pytest.raises(SublevelError) as e:
            s.check(queries=[Query.distance(a, b), Query.collide(a, b, margin=-1.0)])
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert e.value.field == "queries[1].margin"
        with pytest.raises(SublevelError):
            s.check(queries=[Query.distance(a, b)])
    finally:
        s.close()


def test_stream_is_thread_safe(client, balls):
    scene, a, b = balls
    errors = []
    with client.stream(scene) as s:

        def worker(k):
            try:
                for j in range(10):
                    x = 1.0 + 0.1 * k + 0.01 * j
                    (d,) = s.check(poses={b: Pose(t=(x, 0, 0))}, queries=[Query.distance(a, b)])
                    # Each call sends its pose with its query: the answer is for this x.
                    assert abs(d.distance - (x - R1 - R2)) < 1e-8
            except BaseException as e:  # noqa: BLE001
                errors.append(e)

        threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    assert not errors, errors


def test_check_scene(client):
    ball = client.upload_body("ball r=0.5", sphere_body(0.5))
    scene = client.create_scene("check")
    ids = [
        client.add_instance(scene, ball, Pose(t=t))
        for t in [(0, 0, 0), (0.9, 0, 0), (0, 1.3, 0), (10, 0, 0)]
    ]
    # Pairs: 0-1 overlap (centers 0.9 < 1); 0-2 0.3 apart; 1-2 √(0.81+1.69) − 1 ≈ 0.581; 3 far.
    r = client.check_scene(scene, margin=0.4)
    assert r.instances == 4 and r.all_pairs == 6
    assert r.robot is None  # no robot placed (and fitted bodies, which robot checks refuse)
    found = {frozenset((p.first, p.second)): p for p in r.pairs}
    assert set(found) == {frozenset(ids[:2]), frozenset((ids[0], ids[2]))}
    assert [p.distance.distance for p in r.pairs] == sorted(p.distance.distance for p in r.pairs)
    assert found[frozenset(ids[:2])].distance.overlapping
    p02 = found[frozenset((ids[0], ids[2]))].distance
    assert abs(p02.distance - 0.3) < 1e-8
    assert r.candidate_pairs <= r.all_pairs and r.narrow_phase_solves <= r.candidate_pairs
    # Overlapping pairs only; and a pose override for this check only.
    assert [frozenset((p.first, p.second)) for p in client.check_scene(scene).pairs] == [frozenset(ids[:2])]
    r2 = client.check_scene(scene, margin=0.0, instances=[ids[3]], poses={ids[3]: Pose(t=(0.5, 0.5, 0))})
    assert r2.all_pairs == 3 and len(r2.pairs) == 3
    assert {p.first for p in r2.pairs} | {p.second for p in r2.pairs} == set(ids)
    assert client.get_scene(scene).instance(ids[3]).pose.t == (10.0, 0.0, 0.0)


def test_overlap_is_decided_by_a_common_point(client, balls):
    """Overlapping balls (centers 0.1 m apart): a point of both on the line between them decides
    COLLIDE with no solve (collides, distance 0, decided_by_bounds), unary and streamed alike."""
    scene, a, b = balls
    r = client.query(scene, queries=[Query.collide(a, b, 0.0)], poses={b: Pose(t=(0.1, 0.0, 0.0))})
    with client.stream(scene) as s:
        (streamed,) = s.check(queries=[("collide", a, b, 0.0)], poses={b: Pose(t=(0.1, 0.0, 0.0))})
    for c in (r.answers[0], streamed):
        assert isinstance(c, CollideAnswer)
        assert c.collides and c.decided_by_bounds and c.distance == 0.0 and c.solve is None


def test_stream_columns_follow_the_view_and_states(client, balls):
    """The stream in columns: distances of the view's poses (closed form), per-state verdicts."""
    scene, a, b = balls
    with client.stream(scene) as s:
        cols = s.check_columns("distance", [a], [b], poses={b: Pose(t=(2.5, 0, 0))})
        np.testing.assert_allclose(cols.value, [2.5 - R1 - R2], atol=1e-8)
        np.testing.assert_allclose(cols.point_a[0], [R1, 0, 0], atol=1e-7)
        per_state = s.check_columns(
            "collide", [a], [b], margin=0.1, states=[{b: Pose(t=(x, 0, 0))} for x in (0.85, 0.95, 3.0)]
        )
        # Gaps 0.05 (collides), 0.15 (clear), 2.2 (clear, decided by the bounding spheres).
        assert [bool(c.overlapping[0]) for c in per_state] == [True, False, False]
        assert bool(per_state[2].decided_by_bounds[0])
        # The view still holds x = 2.5.
        assert abs(s.check_columns("distance", [a], [b]).value[0] - (2.5 - R1 - R2)) < 1e-8


def test_state_columns_match_the_closed_form(client, balls):
    """Candidate states as one array (QueryRequest.state_columns), answers in one AnswerColumns of
    S x P rows: every state's distance is the closed form |c_a - c_b| - R1 - R2 (0 where the balls
    overlap), over a stream and unary; a badly shaped array is refused before sending."""
    scene, a, b = balls
    centers = np.array([(0.5 + 0.1 * k, 0.05 * (k % 3), -0.1) for k in range(16)])
    state_poses = np.zeros((len(centers), 1, 7))
    state_poses[:, 0, 0] = 1.0  # identity rotation
    state_poses[:, 0, 4:] = centers
    gaps = np.linalg.norm(centers, axis=1) - R1 - R2
    assert (gaps <= 0).any() and (gaps > 0).any()
    with client.stream(scene) as s:
        streamed = s.check_state_columns("distance", [a, b], [b, a], [b], state_poses, cold=True)
    unary = client.query_state_columns(scene, "distance", [a, b], [b, a], [b], state_poses[:, 0, :])
    for cols in (streamed, unary):
        assert len(cols) == 2 * len(centers)
        value = cols.value.reshape(len(centers), 2)
        assert cols.converged.all()
        np.testing.assert_allclose(value, np.stack([np.maximum(gaps, 0.0)] * 2, axis=1), atol=1e-8)
        np.testing.assert_array_equal(cols.overlapping.reshape(-1, 2)[:, 0], gaps <= 0)
    with pytest.raises(ValueError, match="poses"):
        client.query_state_columns(scene, "distance", [a], [b], [a, b], state_poses)
    with pytest.raises(SublevelError) as e:
        client.query_state_columns(scene, "distance", [a], [b], ["no such instance"], state_poses)
    assert e.value.code == grpc.StatusCode.NOT_FOUND and "state_columns.instance_ids[0]" in str(e.value)


def test_cold_states_in_columns_match_the_closed_form(client, balls):
    """Cold pairs across many candidate states (solved four states per SIMD pass on the server):
    every state's distance is the closed form |c_a - c_b| - R1 - R2, 0 where the balls overlap."""
    scene, a, b = balls
    centers = [(0.5 + 0.1 * k, 0.05 * (k % 3), -0.1) for k in range(16)]
    states = [{b: Pose(t=c)} for c in centers]
    with client.stream(scene) as s:
        per_state = s.check_columns("distance", [a], [b], states=states, cold=True)
    assert len(per_state) == len(centers)
    gaps = [np.linalg.norm(c) - R1 - R2 for c in centers]
    assert any(g <= 0 for g in gaps) and any(g > 0 for g in gaps)
    for cols, gap in zip(per_state, gaps):
        assert bool(cols.converged[0])
        assert abs(cols.value[0] - max(gap, 0.0)) < 1e-8
        assert bool(cols.overlapping[0]) == (gap <= 0)
    # The same pairs as a cold BatchQuery in columns at the stored poses.
    cols = client.batch_columns(scene, "distance", [a] * 5, [b] * 5, cold=True)
    np.testing.assert_allclose(cols.value, [1.8 - R1 - R2] * 5, atol=1e-8)
