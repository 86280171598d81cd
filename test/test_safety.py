"""The emergency stop's decisions alone (no ROS): braking, predicted breach, separating moves."""
import numpy as np
from numpy.testing import assert_allclose
import pytest

from scara_collab.core import safety
from scara_collab.core.collision import arm_distance
from scara_collab.core.kinematics import ik
from scara_collab.core.model import load_cell
from scara_collab.core.planning import Timeline
from scara_collab.core.trajectory import joint_move


@pytest.fixture(scope='module')
def cell():
    """Return the cell model, loaded once for the module."""
    return load_cell()


def test_braking_stops_every_joint_at_its_limit_and_no_further(cell):
    """Braking stops every joint at its acceleration limit, v^2 / 2a on; at rest, a hold.

    It lasts the stopping time and its positions integrate its velocities.
    """
    arm = cell.leader
    q, qd = np.array([0.3, -1.0, 0.1]), np.array([1.8, -0.9, 0.4])
    t, pos, vel, acc = safety.braking(arm, q, qd, dt=0.001)
    assert t[0] == 0.0 and t[-1] == pytest.approx(safety.stopping_time(arm, qd))
    assert_allclose(pos[0], q)
    assert_allclose(vel[-1], 0.0)
    assert np.all(np.abs(acc) <= arm.max_acceleration + 1e-12)
    assert_allclose(pos[-1] - q, np.sign(qd) * qd ** 2 / (2 * arm.max_acceleration), atol=1e-12)
    assert_allclose(np.diff(pos, axis=0) / 0.001, 0.5 * (vel[1:] + vel[:-1]), atol=1e-9)
    t, pos, _, _ = safety.braking(arm, q, np.zeros(3))  # at rest: a hold
    assert len(t) == 2
    assert_allclose(pos, [q, q])


def test_first_breach_is_the_first_sample_within_the_margin(cell):
    """The predicted breach is the first sample within the margin, to a prediction step.

    A hold gives none; the stop is due exactly when stopping and latency reach the breach.
    """
    left, right = cell.arms
    q_left = ik(left, [1.8, -0.2, 0.4]).q
    q_right = ik(right, [3.0, 1.2, 0.4]).q
    move = joint_move(right, q_right, ik(right, [1.8, -0.2, 0.4], q_current=q_right).q)
    a, b = Timeline.hold(0.0, q_left), Timeline.of(move, 1.0)
    breach = safety.first_breach(left, a, right, b, 0.1, 0.5)
    times = np.arange(0.5, 1.0 + move.duration, 0.0005)
    d = arm_distance(left, q_left, right, b.at(times))
    first = times[np.argmax(d < 0.1)]
    assert 1.0 < breach and abs(breach - first) <= safety.PREDICTION_STEP
    assert safety.first_breach(left, a, right, Timeline.hold(0.0, q_right), 0.1, 0.5) is None
    assert safety.stop_due(breach - 0.3, breach, stopping=0.26, latency=0.04)
    assert not safety.stop_due(breach - 0.31, breach, stopping=0.26, latency=0.04)
    assert not safety.stop_due(0.0, None, stopping=1.0, latency=1.0)


def test_only_a_move_away_from_the_other_arm_is_separating(cell):
    """Only a move that takes the arm away from the other one is separating."""
    left, right = cell.arms
    q_left = ik(left, [1.8, -0.2, 0.4]).q
    q_right = ik(right, [2.1, 0.05, 0.4]).q
    away = joint_move(right, q_right, ik(right, [2.6, 1.4, 0.4], q_current=q_right).q)
    closer = joint_move(right, q_right, ik(right, [1.95, -0.1, 0.4], q_current=q_right).q)
    assert safety.separating(right, away.q, left, q_left)
    assert not safety.separating(right, closer.q, left, q_left)
    assert not safety.separating(right, np.array([q_right, q_right]), left, q_left)  # no move
