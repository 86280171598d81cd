"""Kinematics against independent references.

The design documents' worked examples, the URDF's own chain, finite differences, and round
trips over many random targets.
"""
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core import kinematics as kin
from scara_collab.core.kinematics import (
    arm_points, base_to_world, det_jacobian, dls_damping, dls_solve, fk, homogeneous, ik,
    ik_both, IKError, jacobian, manipulability, world_to_base)
from scara_collab.core.model import load_cell, parse_urdf

CELL = load_cell()
LEFT, RIGHT = CELL.leader, CELL.follower


def test_the_design_documents_worked_examples():
    """The design documents' worked examples hold: FK and IK of (0, 90 deg), case studies 1, 2.

    The 3 m target is refused with its reason, the 1.5 m one is reached.
    """
    # FK: (0 deg, 90 deg) -> (1.5, 1.0) relative to the base
    assert_allclose(fk(LEFT, [0.0, np.pi / 2, 0.0], frame='base')[:2], [1.5, 1.0], atol=1e-12)
    # IK: (1.5, 1.0) -> (0 deg, 90 deg), elbow up by default
    sol = ik(LEFT, [1.5, 1.0, LEFT.tool_z0], frame='base')
    assert sol.code == kin.OK and sol.elbow == 1
    assert_allclose(sol.q, [0.0, np.pi / 2, 0.0], atol=1e-12)
    # case study 2: world (5, -2) is 3 m from the left base: refused, with the reason
    far = ik(LEFT, [5.0, -2.0, 0.3])
    assert far.code == kin.TOO_FAR and 'outer reach' in far.reasons()
    with pytest.raises(IKError, match='beyond the outer reach'):
        far.unwrap()
    # case study 1: world (2, -3.5) is 1.5 m from the left base: reachable
    assert ik(LEFT, [2.0, -3.5, 0.3]).code == kin.OK


@pytest.mark.parametrize('arm', [LEFT, RIGHT], ids=lambda a: a.name)
def test_fk_matches_the_urdf_chain(arm):
    """FK and the shoulder, elbow and tool points match the URDF's own kinematic chain."""
    urdf = parse_urdf(CELL.urdf)
    rng = np.random.default_rng(11)
    q = rng.uniform(arm.lower, arm.upper, (100, 3))
    pts = arm_points(arm, q)
    assert_allclose(fk(arm, q), pts[:, 2])
    for qi, ptsi in zip(q, pts):
        urdf.update_cfg(dict(zip(arm.joint_names, qi)))
        assert_allclose(ptsi[2], urdf.get_transform(f'{arm.name}_quill', 'world')[:3, 3],
                        atol=1e-12)
        elbow = urdf.get_transform(f'{arm.name}_link_2', 'world')[:3, 3]
        assert_allclose(ptsi[1, :2], elbow[:2], atol=1e-12)
        assert_allclose(ptsi[0], urdf.get_transform(f'{arm.name}_link_1', 'world')[:3, 3],
                        atol=1e-12)


@pytest.mark.parametrize('arm', [LEFT, RIGHT], ids=lambda a: a.name)
def test_ik_round_trip_on_100k_random_targets(arm):
    """IK solves exactly the reachable ones of 100k random FK targets.

    Given the current state it returns those joints; without it, elbow up.
    """
    rng = np.random.default_rng(5)
    q = rng.uniform(arm.lower, arm.upper, (100_000, 3))
    p = fk(arm, q)
    r = np.linalg.norm(world_to_base(arm, p)[:, :2], axis=1)
    reachable = (r >= arm.reach_min) & (r <= arm.reach_max)
    sol = ik(arm, p, q_current=q)
    assert np.array_equal(sol.ok, reachable), 'every reachable target within limits is solved'
    # with the current state given, IK picks the elbow the arm is already in
    assert_allclose(sol.q[reachable], q[reachable], atol=1e-9)
    assert_allclose(fk(arm, sol.q[reachable]), p[reachable], atol=1e-9)
    assert np.all(sol.code[~reachable] == kin.TOO_FAR)
    fresh = ik(arm, p[reachable])  # no current state: elbow up wherever it is in limits
    assert_allclose(fk(arm, fresh.q), p[reachable], atol=1e-9)
    assert np.all(fresh.elbow[fresh.q[:, 1] > 1e-9] == 1)


# strictly inside: a target generated at exactly 2.45 m lands a rounding error outside it
annulus = st.tuples(st.floats(0.807, 2.45 - 1e-9), st.floats(-np.pi, np.pi), st.floats(0.1, 0.7))


@settings(max_examples=300, deadline=None)
@given(annulus)
def test_ik_round_trip_scalar_property(target):
    """Inside the reach annulus IK solves within limits, or refuses on the joint limit only."""
    r, phi, z = target
    base = LEFT.base_position
    p = np.array([base[0] + r * np.cos(phi), base[1] + r * np.sin(phi), z])
    sol = ik(LEFT, p)
    if sol.code == kin.OK:
        assert_allclose(fk(LEFT, sol.q), p, atol=1e-9)
        assert kin.within_limits(LEFT, sol.q)
    else:  # the only refusal left inside this annulus: theta1 beyond +-150 deg for both elbows
        assert sol.code == kin.JOINT_LIMIT
        for q in ik_both(LEFT, p):
            assert not kin.within_limits(LEFT, q)


def test_reach_edges_are_exact():
    """The outer reach edge is exact to 1e-9 m; at the inner one the joint limit refuses."""
    base = LEFT.base_position
    at = np.array([base[0] + LEFT.reach_max, base[1], 0.3])
    assert ik(LEFT, at).code == kin.OK
    assert ik(LEFT, at + [1e-9, 0, 0]).code == kin.TOO_FAR
    # the inner edge allowed by the reach epsilon (0.55 m) needs theta2 beyond 150 deg:
    # the joint limit, not the reach, is the binding rule there (inner limit ~0.807 m)
    assert ik(LEFT, base + [0.6, 0.0, 0.1]).code == kin.JOINT_LIMIT
    assert ik(LEFT, base + [0.5, 0.0, 0.1]).code == kin.TOO_CLOSE
    assert ik(LEFT, base + [0.81, 0.0, 0.1]).code == kin.OK


@pytest.mark.parametrize('target, code', [
    ([np.nan, -2.0, 0.3], kin.NON_FINITE),
    ([2.0, np.inf, 0.3], kin.NON_FINITE),
    ([9.0, -2.0, 0.3], kin.TOO_FAR),
    ([2.1, -2.1, 0.3], kin.TOO_CLOSE),
    ([3.5, -2.0, 0.9], kin.QUILL_RANGE),   # above the quill's top (tool z 0.7)
    ([3.5, -2.0, 0.05], kin.QUILL_RANGE),  # below full travel (tool z 0.1)
    ([-0.3, -2.0, 0.3], kin.JOINT_LIMIT),  # 2.3 m straight behind: theta1 ~ 180 deg
])
def test_refusals_say_which_rule_failed(target, code):
    """Each refused target names the rule that failed, also inside a batch.

    The joints are NaN and the elbow 0; a batch's unwrap names the refused index.
    """
    sol = ik(LEFT, target)
    assert sol.code == code and np.all(np.isnan(sol.q)) and sol.elbow == 0
    batch = ik(LEFT, np.array([target, [3.5, -1.0, 0.3]]))
    assert list(batch.code) == [code, kin.OK]
    with pytest.raises(IKError, match='target 0 of 2'):
        batch.unwrap()


def test_least_displacement_choice_and_elbow_up_preference():
    """Without a current state IK picks elbow up; with one, the elbow nearer to it."""
    p = fk(LEFT, [0.3, -1.2, 0.2])  # an elbow-down posture
    assert ik(LEFT, p).elbow == 1  # no current state: elbow up
    near_down = ik(LEFT, p, q_current=[0.3, -1.0, 0.0])
    assert near_down.elbow == -1
    assert_allclose(near_down.q, [0.3, -1.2, 0.2], atol=1e-12)


def test_scalar_and_vector_paths_agree():
    """The scalar and the vectorised IK give the same codes, joints and elbows."""
    rng = np.random.default_rng(2)
    p = np.c_[rng.uniform(-1, 5, 2000), rng.uniform(-5, 1, 2000), rng.uniform(0, 0.8, 2000)]
    qc = rng.uniform(LEFT.lower, LEFT.upper, (2000, 3))
    for cur in (None, qc):
        batch = ik(LEFT, p, cur)
        for i in range(0, 2000, 7):
            one = ik(LEFT, p[i], None if cur is None else cur[i])
            assert one.code == batch.code[i]
            if one.code == kin.OK:
                assert_allclose(one.q, batch.q[i], atol=1e-12)
                assert one.elbow == batch.elbow[i]


def test_frames_and_homogeneous_transforms():
    """Base and world frames convert both ways, and the homogeneous transforms agree.

    Base-frame IK matches world-frame IK, and an unknown frame is refused.
    """
    p = np.array([[3.0, -1.0, 0.4], [1.0, 2.5, 0.2]])
    for arm in (LEFT, RIGHT):
        assert_allclose(base_to_world(arm, world_to_base(arm, p)), p)
        h, h_inv = homogeneous(arm), homogeneous(arm, inverse=True)
        assert_allclose(h @ h_inv, np.eye(4), atol=1e-15)
        ph = np.c_[p, np.ones(2)]
        assert_allclose((h_inv @ ph.T).T[:, :3], world_to_base(arm, p))
    assert_allclose(world_to_base(LEFT, [2.0, -3.0, 0.2]), [0.0, -1.0, 0.0])
    assert_allclose(world_to_base(RIGHT, [2.0, 1.0, 0.2]), [0.0, -1.0, 0.0])
    q = ik(LEFT, [3.0, -1.0, 0.4]).q
    assert_allclose(ik(LEFT, world_to_base(LEFT, [3.0, -1.0, 0.4]), frame='base').q, q)
    with pytest.raises(ValueError, match='frame'):
        ik(LEFT, [3.0, -1.0, 0.4], frame='tool0')


def test_jacobian_matches_finite_differences():
    """The analytic Jacobian matches central finite differences of FK."""
    rng = np.random.default_rng(9)
    q = rng.uniform(LEFT.lower, LEFT.upper, (500, 3))
    jac = jacobian(LEFT, q)
    eps = 1e-6
    for j in range(3):
        dq = np.zeros(3)
        dq[j] = eps
        num = (fk(LEFT, q + dq) - fk(LEFT, q - dq)) / (2 * eps)
        assert_allclose(jac[:, :, j], num, atol=1e-8)
    planar = jac[:, :2, :2]
    assert_allclose(np.linalg.det(planar), det_jacobian(LEFT, q), atol=1e-12)
    assert_allclose(np.sqrt(np.linalg.det(planar @ np.swapaxes(planar, 1, 2))),
                    manipulability(LEFT, q), atol=1e-9)
    assert_allclose(jacobian(LEFT, q[0]), jac[0])  # one state through the same code


def test_dls_is_exact_away_from_singularity_and_bounded_near_it():
    """DLS equals the exact inverse away from singularity and stays bounded near it.

    The damping grows as the manipulability falls.
    """
    w = np.linspace(0, 1, 101)
    lam = dls_damping(w, 0.5, 0.15)
    assert lam[0] == pytest.approx(0.15) and np.all(lam[w >= 0.5] == 0)
    assert np.all(np.diff(lam) <= 0), 'damping grows as manipulability falls'
    q = np.array([0.4, 1.2, 0.1])  # w = 1.5 sin(1.2) = 1.4: no damping
    v = np.array([0.3, -0.2, 0.05])
    assert_allclose(dls_solve(LEFT, q, v), np.linalg.solve(jacobian(LEFT, q), v))
    near = np.array([0.4, 1e-4, 0.1])  # fully stretched: radial motion is impossible
    radial = np.array([np.cos(0.4), np.sin(0.4), 0.0])
    with np.errstate(all='ignore'):
        exact = np.linalg.pinv(jacobian(LEFT, near)) @ radial
    damped = dls_solve(LEFT, near, radial)
    assert np.linalg.norm(exact) > 1e3 > 10 * np.linalg.norm(damped)
