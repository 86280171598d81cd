"""Dynamics: SPD inertia, Pinocchio on the same URDF, energy balance, FD/ID round trip."""
import dataclasses

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
import pinocchio
import pytest

from scara_collab.core.dynamics import (coriolis, forward_dynamics, friction, gravity,
                                        inverse_dynamics, kinetic_energy, mass_matrix,
                                        potential_energy)
from scara_collab.core.model import expand_xacro, load_cell

PROFILES = ('slim', 'default', 'heavy')
ROBOTS = ('scara_left', 'scara_right')
PAYLOADS = (0.0, 1.0, 2.5)
G = 9.81


def random_states(arm, n, seed):
    """Return ``n`` random (q, qd, qdd) within the joint limits, each (n, 3)."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(arm.lower, arm.upper, size=(n, 3))
    qd = rng.uniform(-1.0, 1.0, size=(n, 3)) * arm.max_velocity
    qdd = rng.uniform(-1.0, 1.0, size=(n, 3)) * arm.max_acceleration
    return q, qd, qdd


def pinocchio_arm(robot, profile, payload=0.0):
    """Build the arm's own URDF in Pinocchio, with a point payload at the quill frame origin."""
    model = pinocchio.buildModelFromXML(
        expand_xacro('scara_arm.urdf.xacro', robot=robot, profile=profile))
    quill = model.getJointId(f'{robot}_gripper_joint')
    model.inertias[quill] = model.inertias[quill] + pinocchio.Inertia(
        payload, np.zeros(3), np.zeros((3, 3)))
    return model, model.createData()


def assert_close_rel(actual, desired, rtol=1e-9):
    """Elementwise closeness relative to the largest entry of ``desired``."""
    assert_allclose(actual, desired, rtol=rtol, atol=rtol * max(1.0, np.abs(desired).max()))


@pytest.mark.parametrize('payload', PAYLOADS)
@pytest.mark.parametrize('profile', PROFILES)
def test_mass_matrix_is_symmetric_positive_definite(profile, payload):
    """M(q) is symmetric positive definite in every profile and with every payload.

    The theta-d3 coupling is exactly zero and M33 is the sliding mass.
    """
    for arm in load_cell(profile).arms:
        q, _, _ = random_states(arm, 2000, seed=1)
        m = mass_matrix(arm, q, payload)
        assert m.shape == (2000, 3, 3)
        assert_array_equal(m, np.swapaxes(m, -1, -2))
        assert np.linalg.eigvalsh(m).min() > 0.0
        # The theta-d3 coupling is exactly zero for a vertical quill; M33 is the sliding mass.
        assert_array_equal(m[:, :2, 2], 0.0)
        assert_allclose(m[:, 2, 2], arm.quill.mass + payload)


@settings(max_examples=200, deadline=None)
@given(u=st.lists(st.floats(0.0, 1.0), min_size=9, max_size=9),
       payload=st.sampled_from(PAYLOADS), profile=st.sampled_from(PROFILES))
def test_spd_and_round_trip_property(u, payload, profile):
    """At any state within the limits M(q) is positive definite and FD inverts ID."""
    arm = load_cell(profile).leader
    u = np.reshape(u, (3, 3))
    q = arm.lower + u[0] * (arm.upper - arm.lower)
    qd = (2.0 * u[1] - 1.0) * arm.max_velocity
    qdd = (2.0 * u[2] - 1.0) * arm.max_acceleration
    assert np.linalg.eigvalsh(mass_matrix(arm, q, payload)).min() > 0.0
    tau = inverse_dynamics(arm, q, qd, qdd, payload)
    assert_close_rel(forward_dynamics(arm, q, qd, tau, payload), qdd, rtol=1e-10)


@pytest.mark.parametrize('payload', PAYLOADS)
@pytest.mark.parametrize('robot', ROBOTS)
@pytest.mark.parametrize('profile', PROFILES)
def test_agrees_with_pinocchio_on_the_same_urdf(profile, robot, payload):
    """M, ID, gravity and FD agree with Pinocchio's CRBA, RNEA, gravity and ABA."""
    arm = load_cell(profile).arm(robot)
    model, data = pinocchio_arm(robot, profile, payload)
    assert model.nq == model.nv == 3
    assert list(model.names)[1:] == list(arm.joint_names)
    assert list(model.idx_qs)[1:] == [0, 1, 2]
    assert_allclose(model.gravity.linear, [0.0, 0.0, -G])
    q, qd, qdd = random_states(arm, 100, seed=2)
    m = mass_matrix(arm, q, payload)
    tau = inverse_dynamics(arm, q, qd, qdd, payload, with_friction=False)
    grav = gravity(arm, q, payload)
    for i in range(len(q)):
        m_pin = pinocchio.crba(model, data, q[i])
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        assert_close_rel(m[i], m_pin)
        assert_close_rel(tau[i], pinocchio.rnea(model, data, q[i], qd[i], qdd[i]))
        assert_close_rel(grav[i], pinocchio.computeGeneralizedGravity(model, data, q[i]))
        assert_close_rel(forward_dynamics(arm, q[i], qd[i], tau[i], payload, with_friction=False),
                         pinocchio.aba(model, data, q[i], qd[i], tau[i]))


def smooth_trajectory(arm, t):
    """Return q, qd, qdd of a smooth sinusoidal path inside the limits, each (len(t), 3)."""
    mid, half = (arm.lower + arm.upper) / 2, (arm.upper - arm.lower) / 2
    amp, w, phase = 0.8 * half, np.array([1.3, 2.1, 3.7]), np.array([0.2, 1.1, -0.4])
    arg = np.outer(t, w) + phase
    return mid + amp * np.sin(arg), amp * w * np.cos(arg), -amp * w ** 2 * np.sin(arg)


@pytest.mark.parametrize('payload', PAYLOADS)
def test_energy_balance_along_a_trajectory(cell, payload):
    """Energy balances along a smooth path: dK/dt and dV/dt are the efforts' power.

    The power of the ID efforts less gravity is dK/dt, that of gravity dV/dt, and K is
    1/2 qd^T M qd.
    """
    arm = cell.leader
    t, dt = np.linspace(0.0, 3.0, 601), 1e-5
    q, qd, qdd = smooth_trajectory(arm, t)
    tau = inverse_dynamics(arm, q, qd, qdd, payload, with_friction=False)
    grav = gravity(arm, q, payload)
    plus, minus = smooth_trajectory(arm, t + dt), smooth_trajectory(arm, t - dt)
    k_dot = (kinetic_energy(arm, *plus[:2], payload)
             - kinetic_energy(arm, *minus[:2], payload)) / (2 * dt)
    v_dot = (potential_energy(arm, plus[0], payload)
             - potential_energy(arm, minus[0], payload)) / (2 * dt)
    power = np.einsum('ij,ij->i', qd, tau - grav)
    assert_allclose(k_dot, power, atol=1e-5 * np.abs(power).max())
    assert_allclose(v_dot, np.einsum('ij,ij->i', qd, grav), atol=1e-6)
    assert_allclose(kinetic_energy(arm, q, qd, payload),
                    0.5 * np.einsum('ij,ijk,ik->i', qd, mass_matrix(arm, q, payload), qd))


def test_coriolis_from_numerical_christoffel_symbols_and_skew_symmetry(cell):
    """Coriolis forces follow from numerical Christoffel symbols; dM/dt - 2C is skew."""
    arm, h, payload = cell.follower, 1e-6, 1.0
    q, qd, _ = random_states(arm, 50, seed=4)
    # dm[n, k] = dM/dq_k at state n, by central differences of mass_matrix.
    dm = np.stack([(mass_matrix(arm, q + h * e, payload) - mass_matrix(arm, q - h * e, payload))
                   / (2 * h) for e in np.eye(3)], axis=1)
    christoffel = 0.5 * (np.einsum('nkij->nijk', dm) + np.einsum('njik->nijk', dm)
                         - np.einsum('nijk->nijk', dm))
    c_matrix = np.einsum('nijk,nk->nij', christoffel, qd)
    assert_allclose(coriolis(arm, q, qd, payload), np.einsum('nij,nj->ni', c_matrix, qd),
                    atol=1e-7)
    m_dot = np.einsum('nkij,nk->nij', dm, qd)
    n_matrix = m_dot - 2 * c_matrix
    assert_allclose(n_matrix, -np.swapaxes(n_matrix, 1, 2), atol=1e-7)


def test_free_motion_conserves_energy_and_friction_dissipates(cell):
    """Free motion (RK4) conserves energy; with friction the energy falls at every step."""
    arm, payload, dt = cell.leader, 2.5, 1e-3
    state0 = np.array([[0.2, 1.0, 0.3], [1.5, -1.0, 0.2]])   # rows: q, qd

    def rk4(state, friction_on):
        def f(s):
            return np.stack([s[1], forward_dynamics(arm, s[0], s[1], np.zeros(3), payload,
                                                    with_friction=friction_on)])
        k1 = f(state)
        k2 = f(state + dt / 2 * k1)
        k3 = f(state + dt / 2 * k2)
        k4 = f(state + dt * k3)
        return state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def energy(s):
        return kinetic_energy(arm, s[0], s[1], payload) + potential_energy(arm, s[0], payload)

    free, damped = state0, state0
    energies_free, energies_damped = [energy(state0)], [energy(state0)]
    for _ in range(500):
        free, damped = rk4(free, False), rk4(damped, True)
        energies_free.append(energy(free))
        energies_damped.append(energy(damped))
    assert_allclose(energies_free, energies_free[0], rtol=1e-9)
    assert np.all(np.diff(energies_damped) < 0.0)


@pytest.mark.parametrize('payload', PAYLOADS)
def test_forward_dynamics_inverts_inverse_dynamics_vectorised(cell, payload):
    """FD inverts ID for 1000 states of both arms, with and without friction."""
    for arm in cell.arms:
        q, qd, qdd = random_states(arm, 1000, seed=5)
        for with_friction in (True, False):
            tau = inverse_dynamics(arm, q, qd, qdd, payload, with_friction=with_friction)
            assert tau.shape == (1000, 3)
            back = forward_dynamics(arm, q, qd, tau, payload, with_friction=with_friction)
            assert_allclose(back, qdd, atol=1e-9)


def test_vectorised_equals_per_row(cell):
    """Every function gives for N states what it gives for each row alone.

    A per-state payload array broadcasts like the states do.
    """
    arm, payload = cell.follower, 1.0
    q, qd, qdd = random_states(arm, 20, seed=6)
    tau = inverse_dynamics(arm, q, qd, qdd, payload)
    batched = {
        'm': mass_matrix(arm, q, payload), 'c': coriolis(arm, q, qd, payload),
        'g': gravity(arm, q, payload), 'f': friction(arm, qd), 'tau': tau,
        'qdd': forward_dynamics(arm, q, qd, tau, payload),
        'k': kinetic_energy(arm, q, qd, payload), 'v': potential_energy(arm, q, payload)}
    for i in range(len(q)):
        row = {
            'm': mass_matrix(arm, q[i], payload), 'c': coriolis(arm, q[i], qd[i], payload),
            'g': gravity(arm, q[i], payload), 'f': friction(arm, qd[i]),
            'tau': inverse_dynamics(arm, q[i], qd[i], qdd[i], payload),
            'qdd': forward_dynamics(arm, q[i], qd[i], tau[i], payload),
            'k': kinetic_energy(arm, q[i], qd[i], payload),
            'v': potential_energy(arm, q[i], payload)}
        for key, value in row.items():
            assert np.shape(value) == np.shape(batched[key][i]), key
            assert_allclose(value, batched[key][i], rtol=1e-12, atol=1e-12, err_msg=key)
    # A per-state payload array broadcasts like the states do.
    payloads = np.linspace(0.0, 2.5, len(q))
    per_row = [inverse_dynamics(arm, q[i], qd[i], qdd[i], payloads[i]) for i in range(len(q))]
    assert_allclose(inverse_dynamics(arm, q, qd, qdd, payloads), per_row, rtol=1e-12)


def test_friction_opposes_motion(cell):
    """Friction has the sign of the velocity, never does negative work, and ID adds it."""
    arm = cell.leader
    _, qd, _ = random_states(arm, 500, seed=7)
    f = friction(arm, qd)
    assert_array_equal(np.sign(f), np.sign(qd))
    assert_allclose(f, arm.viscous * qd + arm.coulomb * np.sign(qd))
    assert_array_equal(friction(arm, np.zeros(3)), 0.0)
    # The work friction costs is never negative, and the ID adds exactly F to the effort.
    assert np.all(np.einsum('ij,ij->i', f, qd) >= 0.0)
    q, _, qdd = random_states(arm, 500, seed=8)
    assert_allclose(inverse_dynamics(arm, q, qd, qdd)
                    - inverse_dynamics(arm, q, qd, qdd, with_friction=False), f, atol=1e-12)


@pytest.mark.parametrize('payload', PAYLOADS)
def test_gravity_acts_only_on_the_quill(cell, payload):
    """Gravity acts only on the quill, m g upward, and holds it still.

    ID at rest equals G, FD under G stands still, and V = -m g d3.
    """
    for arm in cell.arms:
        q, _, _ = random_states(arm, 100, seed=9)
        grav = gravity(arm, q, payload)
        assert_array_equal(grav[:, :2], 0.0)
        # The quill axis points down: holding it takes an upward, i.e. negative, joint force.
        assert_allclose(grav[:, 2], -(arm.quill.mass + payload) * G)
        assert_allclose(gravity(arm, q[0], payload, g=1.62)[2], -(arm.quill.mass + payload) * 1.62)
        # Static hold: the ID at rest equals G, and G makes the quill stand still in FD.
        zero = np.zeros_like(q)
        assert_allclose(inverse_dynamics(arm, q, zero, zero, payload), grav, atol=1e-12)
        assert_allclose(forward_dynamics(arm, q, zero, grav, payload), 0.0, atol=1e-12)
        assert_allclose(potential_energy(arm, q, payload),
                        -(arm.quill.mass + payload) * G * q[:, 2])


def test_bad_input_is_refused(cell):
    """Wrong state shapes and a tilted base are refused."""
    arm = cell.leader
    with pytest.raises(ValueError, match='shape'):
        mass_matrix(arm, [0.0, 0.0])
    with pytest.raises(ValueError, match='shape'):
        inverse_dynamics(arm, np.zeros(3), np.zeros((4, 2)), np.zeros(3))
    tilted = np.eye(4)
    tilted[:3, :3] = [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]
    with pytest.raises(ValueError, match='upright'):
        gravity(dataclasses.replace(arm, base=tilted), np.zeros(3))


def test_parameters_come_from_the_model(cell):
    """Doubling the quill's mass in the model changes M and G accordingly."""
    arm = cell.leader
    quill = dataclasses.replace(arm.quill, mass=2 * arm.quill.mass)
    heavier = dataclasses.replace(arm, quill=quill)
    q = np.array([0.3, 0.7, 0.2])
    assert mass_matrix(heavier, q)[2, 2] == pytest.approx(2 * arm.quill.mass)
    assert mass_matrix(heavier, q)[0, 0] > mass_matrix(arm, q)[0, 0]
    assert gravity(heavier, q)[2] == pytest.approx(2 * gravity(arm, q)[2])
