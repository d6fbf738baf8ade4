"""The fidelity dial against a real server: the MotionBenchMaker Panda in scene 1 of each scenario,
its 200 labelled configurations per scene checked at every level against the mesh-exact labels of
data/robots/mbm_panda/labels_obj.csv (pinocchio + coal on the collision meshes): no level misses a
labelled collision, a free verdict at any level is free on the meshes and says "mesh", a false
collision says the level it rests on, and a conservative distance never exceeds the labelled one.
Bad levels and tolerances are refused naming the argument or the field."""

import grpc
import numpy as np
import pytest

from sublevel_client import SublevelError

from test_robots import JOINTS, SCENARIOS, labels, mbm_scenes, panda  # noqa: F401 (fixtures)

LEVELS = [("mesh", 0.0), ("bodies", 0.0), ("spheres", 0.0), ("spheres", 0.01), ("spheres", 0.2)]


@pytest.mark.parametrize("level,tolerance", LEVELS)
def test_no_level_misses_a_labelled_collision(client, panda, mbm_scenes, level, tolerance):  # noqa: F811
    false_collisions = 0
    for scenario in SCENARIOS:
        lab = labels(scenario, 1)
        c = client.check_configurations(
            panda.robot_id, lab["q"], scene=mbm_scenes[scenario], joint_names=JOINTS,
            fidelity=level, sphere_tolerance=tolerance,
        )
        # No miss: every labelled collision collides at this level.
        assert np.all(c.collides[lab["collides"]]), f"{level}: a labelled collision answered free in {scenario}"
        assert np.all(c.world[lab["collides_world"]]), f"{level}: a world miss in {scenario}"
        free = ~c.collides
        assert all(c.fidelity[i] == "mesh" for i in np.flatnonzero(free)), "a free verdict is the meshes' own"
        wrong = c.collides & ~lab["collides"]
        false_collisions += int(wrong.sum())
        assert all(c.fidelity[i] == level for i in np.flatnonzero(wrong)), (
            f"{level}: a false collision not labelled with its level in {scenario}"
        )
        if level == "mesh":
            np.testing.assert_array_equal(c.collides, lab["collides"])
        d = client.check_configurations(
            panda.robot_id, lab["q"], scene=mbm_scenes[scenario], joint_names=JOINTS, distance=True,
            fidelity=level, sphere_tolerance=tolerance,
        )
        both_free = ~d.world & ~lab["collides_world"]
        # A certified lower bound of the meshes' distance (labels printed to 1e-6 m).
        assert np.all(d.distance[both_free] <= lab["dist"][both_free] + 1e-5), f"{level}: distance above the meshes'"
    if level == "mesh":
        assert false_collisions == 0
    else:
        # The scenes' labels sit near contact: every conservative level has false collisions here.
        assert false_collisions > 0


def test_bad_levels_are_refused_naming_the_field(client, panda):  # noqa: F811
    q = np.zeros((1, 7))
    with pytest.raises(ValueError, match="`fidelity`"):
        client.check_configurations(panda.robot_id, q, joint_names=JOINTS, fidelity="voxels")
    with pytest.raises(ValueError, match="`sphere_tolerance`"):
        client.check_configurations(panda.robot_id, q, joint_names=JOINTS, fidelity="spheres", sphere_tolerance=-1)
    for level, tolerance in [("spheres", 0.001), ("spheres", 2.0), ("bodies", 0.05)]:
        with pytest.raises(SublevelError) as e:
            client.check_configurations(
                panda.robot_id, q, joint_names=JOINTS, fidelity=level, sphere_tolerance=tolerance
            )
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT
        assert "fidelity.tolerance" in str(e.value)


def test_a_plan_at_the_spheres_level_is_certified_on_the_meshes(client, panda, mbm_scenes):  # noqa: F811
    lab = labels("table_pick", 1)
    free = np.flatnonzero(~lab["collides"])
    start, goal = lab["q"][free[0]], lab["q"][free[-1]]
    spheres = client.check_configurations(
        panda.robot_id, np.stack([start, goal]), scene=mbm_scenes["table_pick"], joint_names=JOINTS,
        fidelity="spheres", sphere_tolerance=0.01,
    )
    if spheres.collides.any():
        pytest.skip("the labelled ends sit within the sphere tolerance of contact")
    r = client.plan(
        panda.robot_id, scene=mbm_scenes["table_pick"], start=start, goal=goal, joint_names=JOINTS, timeout=5.0,
        fidelity="spheres", sphere_tolerance=0.01,
    )
    assert r.status == "solved"
    assert r.certified
    # Every waypoint free on the meshes (the server's mesh level).
    c = client.check_configurations(panda.robot_id, r.path, scene=mbm_scenes["table_pick"], joint_names=r.joint_names)
    assert not c.collides.any()
