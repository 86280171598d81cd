"""Servo laws: computed torque inverts the core dynamics; PID gains and anti-windup."""
import numpy as np
import numpy.testing as npt

from scara_collab.core.config import load_config
from scara_collab.core.dynamics import forward_dynamics, mass_matrix
from scara_collab.sim.controllers import (
    applied_efforts, ComputedTorqueController, joint_gains, PidController, smooth_friction)


def test_gains_come_from_controllers_yaml():
    """The PID gains per joint come from controllers.yaml."""
    ctl = load_config('controllers')
    npt.assert_array_equal(joint_gains(ctl['pid'], 'kp'), [15.0, 15.0, 10.0])
    npt.assert_array_equal(joint_gains(ctl['pid'], 'ki'), [0.5, 0.5, 0.1])
    npt.assert_array_equal(joint_gains(ctl['pid'], 'kd'), [2.0, 2.0, 1.0])


def test_computed_torque_on_the_reference_gives_the_reference_acceleration(cell):
    """With zero error, forward dynamics of the CT torque returns qdd_ref (exact model)."""
    rng = np.random.default_rng(0)
    ct = ComputedTorqueController(cell.arms, kp=[400.0] * 3, kd=[40.0] * 3,
                                  friction_smoothing=1e-9)  # tanh == sign away from 0
    assert ct.shared
    q = rng.uniform(-2.0, 2.0, size=(2, 3))
    qd = rng.uniform(-1.0, 1.0, size=(2, 3))
    qdd_ref = rng.uniform(-3.0, 3.0, size=(2, 3))
    payload = np.array([0.0, 2.5])
    tau = ct(q, qd, q, qd, qdd_ref, payload)
    for i, arm in enumerate(cell.arms):
        npt.assert_allclose(forward_dynamics(arm, q[i], qd[i], tau[i], payload=payload[i]),
                            qdd_ref[i], atol=1e-9)
    # the per-arm path (arms with different parameters) gives the same torques
    ct.shared = False
    npt.assert_allclose(ct(q, qd, q, qd, qdd_ref, payload), tau, atol=1e-12)


def test_computed_torque_feedback_is_mass_weighted(cell):
    """The computed-torque feedback is M(q) times the PD term; no error, no feedback."""
    ct = ComputedTorqueController(cell.arms, kp=[400.0] * 3, kd=[40.0] * 3)
    q = np.zeros((2, 3))
    err = np.array([[1e-3, 0.0, 0.0], [0.0, 0.0, 0.0]])
    tau = ct(q, q, q + err, q, q, np.zeros(2)) - ct(q, q, q, q, q, np.zeros(2))
    npt.assert_allclose(tau[0], mass_matrix(cell.leader, q[0]) @ (400.0 * err[0]), atol=1e-9)
    assert not tau[1].any()


def test_pid_law_and_anti_windup():
    """The PID law sums the P, I and D terms; the integral is clamped at the effort limit.

    ``reset`` zeroes one arm's integral.
    """
    pid = PidController([15.0, 15.0, 10.0], [0.5, 0.5, 0.1], [2.0, 2.0, 1.0],
                        max_effort=[400.0, 200.0, 300.0], arms=2)
    q, ref = np.zeros((2, 3)), np.full((2, 3), 0.1)
    tau = pid(q, q, ref, q, 0.001)
    npt.assert_allclose(tau[0], [1.5 + 0.5 * 1e-4, 1.5 + 0.5 * 1e-4, 1.0 + 0.1 * 1e-4])
    for _ in range(100):
        pid(q, q, np.full((2, 3), 1e6), q, 1.0)
    npt.assert_allclose(pid.ki * pid.integral, [[400.0, 200.0, 300.0]] * 2)
    pid.reset(0)
    assert not pid.integral[0].any() and pid.integral[1].all()


def test_smooth_friction_is_odd_and_tends_to_viscous_plus_coulomb():
    """The smoothed friction is odd, zero at rest, and viscous plus Coulomb away from zero."""
    v, c = np.array([0.1, 0.1, 5.0]), np.array([0.2, 0.2, 1.0])
    qd = np.array([1.0, -1.0, 0.5])
    npt.assert_allclose(smooth_friction(v, c, qd, 0.01), v * qd + c * np.sign(qd), rtol=1e-9)
    npt.assert_allclose(smooth_friction(v, c, -qd, 0.01), -smooth_friction(v, c, qd, 0.01))
    assert not smooth_friction(v, c, np.zeros(3), 0.01).any()


def test_the_physics_loop_applies_the_same_friction():
    """``applied_efforts`` (plain floats, every physics step) is ``tau - smooth_friction``."""
    rng = np.random.default_rng(3)
    v, c = rng.uniform(0.0, 5.0, 6), rng.uniform(0.0, 2.0, 6)
    for _ in range(20):
        tau, qd = rng.normal(0.0, 50.0, 6), rng.normal(0.0, 0.05, 6)
        npt.assert_allclose(applied_efforts(tau.tolist(), v.tolist(), c.tolist(), qd.tolist(),
                                            0.01),
                            tau - smooth_friction(v, c, qd, 0.01), rtol=1e-13, atol=1e-12)
