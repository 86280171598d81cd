"""The servo's speed scaling, in the simulator: each arm's trajectory on its own clock.

A line run at a factor that falls to 0 and comes back: the tool stays on the line, the
reference never asks a joint beyond its velocity or acceleration limit, the arm stands still
on its path while the factor is 0 and goes on from there without a jump, and the model's lag
is what the slowdown cost. A waiting move starts on the arm's clock; an arm never slowed has no
clock at all.
"""
import dataclasses

import numpy as np
import pytest

from scara_collab.core.config import load_config
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.trajectory import line_move, segment_deviation
from scara_collab.sim import CellSim

LEFT, RIGHT = 'scara_left', 'scara_right'


@pytest.fixture
def sim(cell):
    """Return a cell with a stopped belt and no feed; the leader's tool at (3.0, -1.3, 0.4)."""
    still = dataclasses.replace(cell, belt=dataclasses.replace(cell.belt, speed=0.0))
    with CellSim(still, dict(load_config('simulation'), feed_interval=0.0)) as s:
        s.reset_arm(LEFT, ik(still.leader, [3.0, -1.3, 0.4]).q)
        yield s


def _profile(t: float) -> float:
    """Return the factor asked over the move: full, half, stopped, full again."""
    if t < 0.4:
        return 1.0
    if t < 0.9:
        return 0.5
    if t < 1.6:
        return 0.0
    return 1.0


def test_a_scaled_line_keeps_its_path_and_limits_stops_on_it_and_resumes_without_a_jump(sim):
    """The chain rule on the trajectory's own clock: path kept, limits kept, no catch-up."""
    arm = sim.cell.leader
    q0 = sim.arm_state(LEFT)[0]
    start, goal = fk(arm, q0), np.array([2.2, -0.6, 0.4])
    line = line_move(arm, q0, goal)
    t0 = sim.time
    sim.execute(LEFT, t0 + line.t, line.q, line.qd, line.qdd, 'line', 0.0)
    servo, a = sim.servo, 0
    refs, tips, lags, held = [], [], [], []
    while sim.active(LEFT) and sim.time < t0 + line.duration + 5.0:
        servo.scale(LEFT, _profile(sim.time - t0))
        sim.step(4)  # one servo tick
        refs.append((sim.time, *servo.reference(a)))
        tips.append(fk(arm, sim.arm_state(LEFT)[0]))
        lags.append(sim.motion[LEFT].lag)
        held.append(bool(servo.held_back))
    assert not sim.active(LEFT)
    np.testing.assert_allclose(tips[-1], goal, atol=2e-3)
    # on the line all along (the executed tool, as the unscaled run keeps it)
    assert max(segment_deviation(np.array(tips), start, goal)) < 2e-3
    # never beyond the limits, even while the factor ramps
    qd = np.array([r[2] for r in refs])
    qdd = np.array([r[3] for r in refs])
    assert np.all(np.abs(qd) <= arm.max_velocity * 1.001)
    assert np.all(np.abs(qdd) <= arm.max_acceleration * 1.02)
    # stopped on the path while the factor is 0, then on from there: no jump, no catch-up
    times = np.array([r[0] for r in refs]) - t0
    still = (times > 1.3) & (times < 1.6)
    assert np.all(np.abs(qd[still]) < 1e-9)
    q_ref = np.array([r[1] for r in refs])
    assert np.max(np.abs(np.diff(q_ref, axis=0))) < arm.max_velocity.max() * 0.004 + 1e-9
    # what the slowdown cost: about a quarter s at half speed and 0.7 s stopped, as the lag
    assert 0.6 < lags[-1] < 1.3
    # on this line the slowdowns keep up with braking (the arm's stopping time falls as
    # braking at its limits would make it): nothing for the bridge to brake
    assert not any(held)


def test_a_waiting_move_starts_when_the_arms_clock_reaches_its_start(sim):
    """Stopped before its start, a move waits on the arm's clock, not on sim time."""
    arm = sim.cell.leader
    q0 = sim.arm_state(LEFT)[0]
    line = line_move(arm, q0, [2.6, -0.9, 0.4])
    t0 = sim.time
    sim.servo.scale(LEFT, 0.0)
    sim.execute(LEFT, t0 + 0.2 + line.t, line.q, line.qd, line.qdd, 'later', t0 + 0.2)
    sim.step(500)  # 0.5 s: the clock stood still before the start
    assert sim.motion[LEFT].running is None and sim.motion[LEFT].waiting is not None
    assert sim.motion[LEFT].lag == pytest.approx(0.5, abs=0.01)
    sim.servo.scale(LEFT, 1.0)
    sim.step(300)
    assert sim.motion[LEFT].running is not None  # started 0.2 s of its clock later


def test_an_arm_never_slowed_has_no_clock_and_an_idle_arm_builds_no_lag(sim):
    """Full speed costs nothing; holding with nothing to do, a slowdown costs no time."""
    sim.step(100)
    assert sim.servo.clocks == {}
    sim.servo.coupling = 'arm'  # the arms hold apart: each its own factor
    sim.servo.scale(RIGHT, 0.0)
    sim.step(200)
    assert sim.motion[RIGHT].lag == 0.0 and sim.servo.speed(RIGHT) == 0.0
    assert sim.motion[LEFT].lag == 0.0 and sim.servo.speed(LEFT) == 1.0  # on sim time


def _both_move(sim):
    """Start a line of each arm now (their paths stay apart); return the moves and the start."""
    cell = sim.cell
    sim.reset_arm(RIGHT, ik(cell.follower, [3.0, 1.3, 0.4]).q)
    moves = {LEFT: line_move(cell.leader, sim.arm_state(LEFT)[0], [2.2, -0.6, 0.4]),
             RIGHT: line_move(cell.follower, sim.arm_state(RIGHT)[0], [3.6, 0.8, 0.4])}
    t0 = sim.time
    for robot, move in moves.items():
        sim.execute(robot, t0 + move.t, move.q, move.qd, move.qdd, robot, 0.0)
    return moves, t0


def test_coupled_arms_slow_in_step_so_their_schedule_against_each_other_holds(sim):
    """One factor for both arms: their clocks take one rate, the slower arm's, to the bit."""
    moves, t0 = _both_move(sim)
    servo = sim.servo
    servo.coupling = 'cell'
    lags = []
    while sim.active(LEFT) and sim.active(RIGHT):
        factor = _profile(sim.time - t0)
        for robot in (LEFT, RIGHT):
            servo.scale(robot, factor)
        sim.step(4)
        lags.append((sim.motion[LEFT].lag, sim.motion[RIGHT].lag))
        assert servo.speed(LEFT) == servo.speed(RIGHT)
    lags = np.array(lags)
    assert np.all(lags[:, 0] == lags[:, 1]) and lags[-1, 0] > 0.3


def test_arms_whose_paths_stay_apart_each_run_at_their_own_factor(sim):
    """Per arm: the right arm stopped by its factor, the left one runs its move at full speed.

    Their paths keep the margin at any timing, so nothing ties one arm's clock to the other's;
    the cell's margin holds however far the stopped arm falls behind.
    """
    moves, t0 = _both_move(sim)
    servo = sim.servo
    servo.coupling = 'arm'
    servo.scale(RIGHT, 0.0)
    while sim.active(LEFT):
        sim.step(4)
        assert not servo.coupled
    assert sim.time - t0 == pytest.approx(moves[LEFT].t[-1], abs=0.01)  # on time
    assert sim.motion[LEFT].lag == pytest.approx(0.0, abs=1e-9)
    assert servo.speed(RIGHT) == 0.0 and sim.motion[RIGHT].lag > 0.5 * moves[LEFT].t[-1]
    assert sim.active(RIGHT)  # held on its path, its move still to run
