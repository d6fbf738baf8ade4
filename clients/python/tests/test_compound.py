"""Compound bodies (a containment tree of sos-convex bodies) through the client: the
bundled compound chair and human are uploaded and queried; the answer carries its tree bounds.

Reference: the distance does not depend on the order of the pair (the leaf pairs are the same),
and the bounds enclose it; the Rust integration tests check it against brute force over all leaf
pairs (tests/it/service_compound.rs)."""

from __future__ import annotations

import math
from pathlib import Path

from sublevel_client import Pose, TreeAnswer

COMPOUND = Path(__file__).resolve().parents[3] / "data" / "compound"


def test_compound_chair_against_compound_human(client):
    chair = client.upload("chair_101.compound", str(COMPOUND / "chair_101.json"))
    human = client.upload("human_10.compound", str(COMPOUND / "human_10.json"))
    assert chair.nodes > 1 and human.nodes > 1 and not chair.nonconvex
    scene = client.create_scene("compound")
    c = client.add_instance(scene, chair.body_id, Pose(t=(1.1, 0.1, 0.0)))
    h = client.add_instance(scene, human.body_id, Pose.identity())
    d = client.distance(scene, c, h)
    assert isinstance(d.tree, TreeAnswer)
    assert d.converged and d.tree.within_tolerance
    assert 0.0 < d.distance < 2.0
    assert d.tree.lower <= d.tree.upper and abs(d.tree.upper - d.distance) < 1e-6
    assert d.tree.leaves is not None and d.tree.level >= 1
    r = client.distance(scene, h, c)
    assert abs(r.distance - d.distance) < 1e-6
    assert r.tree.leaves == (d.tree.leaves[1], d.tree.leaves[0])
    g = client.growth(scene, c, h)
    assert g.separated and math.isinf(g.value) and g.tree is not None
