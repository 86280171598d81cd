"""The collision monitor's rules alone (core/stop_rules.py): the forecast, the standing stop."""
import numpy as np
import pytest

from scara_collab.core.mirror import mirror_joints
from scara_collab.core.stop_rules import BreachForecast, StopLatch


def test_a_stop_of_the_kind_that_stands_changes_nothing_and_counts_once():
    """A second protective stop while one stands is no news; the count stays 1."""
    latch = StopLatch(resume_after=0.3)
    (begin,) = latch.stop('protective', 'predicted breach', 2.0)
    assert (begin.kind, begin.state, begin.time) == ('protective', 'begin', 2.0)
    assert begin.since is None
    assert latch.stop('protective', 'again', 2.1) == []
    assert latch.stopped and latch.reason == 'predicted breach' and latch.since == 2.0
    assert latch.counts == {'protective': 1, 'emergency': 0}


def test_an_emergency_overrides_a_protective_stop_and_nothing_overrides_it():
    """Protective then emergency: the protective one ends first; an emergency stays."""
    latch = StopLatch(resume_after=0.3)
    latch.stop('protective', 'p', 1.0)
    end, begin = latch.stop('emergency', 'margin broken', 1.5)
    assert (end.kind, end.state, end.since, end.text) == ('protective', 'end', 1.0,
                                                          'overridden by an emergency stop')
    assert (begin.kind, begin.state) == ('emergency', 'begin')
    assert latch.stop('protective', 'p', 1.6) == [] and latch.kind == 'emergency'
    assert latch.calm(5.0, True, True, 0.5) == []  # an emergency never resumes by itself
    (cleared,) = latch.end('cleared', 6.0)
    assert (cleared.kind, cleared.since) == ('emergency', 1.5) and not latch.stopped
    assert latch.end('again', 6.1) == []


def test_a_protective_stop_resumes_after_resume_after_of_calm_and_restarts_when_unsettled():
    """Calm (apart and at rest) must last ``resume_after``; any break starts it over."""
    latch = StopLatch(resume_after=0.3)
    latch.stop('protective', 'p', 0.0)
    assert latch.calm(1.0, True, True, 0.4) == []        # calm from 1.0
    assert latch.calm(1.2, True, False, 0.4) == []       # moving: over
    assert latch.calm(1.3, True, True, 0.4) == []        # calm from 1.3
    latch.unsettled()                                     # an unusable state
    assert latch.calm(1.5, True, True, 0.4) == []        # calm from 1.5
    assert latch.calm(1.79, True, True, 0.4) == []
    (end,) = latch.calm(1.8, True, True, 0.4)
    assert end.state == 'end' and end.text.startswith('valid states, arms at rest 0.400 m apart')
    assert not latch.stopped


def test_an_unknown_kind_is_refused():
    """Only protective and emergency stops exist."""
    with pytest.raises(ValueError, match='unknown stop kind'):
        StopLatch(0.3).stop('soft', 'x', 0.0)


def test_the_forecast_stops_a_committed_move_into_the_other_arm_before_the_breach(cell):
    """A move heard to run into the other arm gives a reason to stop before the breach."""
    lead = cell.leader
    home, into = np.array([0.0, 1.5708, 0.0]), np.array([1.0, 0.0, 0.0])
    q_foll = mirror_joints(into)  # the follower waits over the belt's middle, where ``into`` is
    forecast = BreachForecast(cell.arms, cell.safety_margin, dt=0.001)
    rest = np.zeros(3)
    assert forecast.reason_to_stop(0.0, (home, q_foll), (rest, rest), 0.05) is None
    t = np.linspace(0.0, 2.0, 21)
    path = home + np.outer(t / 2.0, into - home)
    forecast.on_trajectory(lead.name, 'scara_left/1', 0.0, t, path, 0.0, home)
    velocity = (into - home) / 2.0
    why, when = None, None
    for stamp in np.arange(0.0, 2.0, 0.01):
        q = home + (stamp / 2.0) * (into - home)
        why = forecast.reason_to_stop(stamp, (q, q_foll), (velocity, rest), 0.05)
        if why is not None:
            when = stamp
            break
    assert why is not None and why.startswith('predicted: the commanded moves (scara_left')
    assert forecast.breach is not None and when < forecast.breach
    # an arm that does not follow the heard move is no ground for a prediction
    assert forecast.reason_to_stop(when + 0.01, (home, q_foll), (rest, rest), 0.05) is None
