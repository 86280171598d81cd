"""The collision monitor's decisions, without ROS: when to stop, and the stop that stands.

:class:`BreachForecast` predicts from the arms' committed motion (as heard: the committed-motion
model, :class:`scara_collab.core.motion.Heard`) whether the margin will break sooner than the
arms can brake, and says why (:meth:`BreachForecast.reason_to_stop`).

:class:`StopLatch` keeps the stop that stands. One stands at a time, of one of two kinds:

- **protective**: the arms are held where they are (a predicted breach, an unusable or missing
  joint state); it ends by itself once the states are valid and the arms at rest and apart for
  ``resume_after`` sim seconds (:meth:`StopLatch.calm`), or when cleared;
- **emergency**: the margin is broken, or someone asked for it; it stands until cleared.

An emergency overrides a protective stop (which then ends); a stop of the kind that stands
already changes nothing. Each change is returned as a :class:`StopChange` for the node to
publish (``emergency_stop`` / ``protective_stop``, ``~/stops``) and log.

>>> latch = StopLatch(resume_after=0.5)
>>> [(c.kind, c.state) for c in latch.stop('protective', 'predicted', 1.0)]
[('protective', 'begin')]
>>> [(c.kind, c.state) for c in latch.stop('emergency', 'margin broken', 1.1)]
[('protective', 'end'), ('emergency', 'begin')]
>>> latch.kind, latch.counts
('emergency', {'protective': 1, 'emergency': 1})
"""
from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core import safety
from scara_collab.core.model import ArmModel
from scara_collab.core.motion import Heard

KINDS = ('protective', 'emergency')
#: rad or m: a prediction is used only while both arms are this close to it
TRACKING = 0.02


@dataclass(frozen=True)
class StopChange:
    """A stop that begins or ends: its kind, ``'begin'`` or ``'end'``, when and why.

    :ivar since: for an end, when the stop began (sim s); None for a begin.
    """

    kind: str
    state: str
    time: float
    text: str
    since: Optional[float] = None


class StopLatch:
    """The standing stop and its counts (see the module docstring).

    :param resume_after: sim s the arms must be calm before a protective stop ends by itself.
    """

    def __init__(self, resume_after: float):
        """No stop yet."""
        self.resume_after = float(resume_after)
        self.kind = ''  # the standing stop's kind, '' if none
        self.reason = ''
        self.since: Optional[float] = None
        self.counts: Dict[str, int] = {k: 0 for k in KINDS}
        self._calm_since: Optional[float] = None  # valid, at rest, apart since (sim s)

    @property
    def stopped(self) -> bool:
        """True while a stop (either kind) stands."""
        return bool(self.kind)

    def stop(self, kind: str, text: str, now: float) -> List[StopChange]:
        """Begin a stop of ``kind`` for ``text`` at ``now``; return the changes (maybe none)."""
        if kind not in KINDS:
            raise ValueError(f'unknown stop kind {kind!r}; one of {KINDS}')
        if self.kind == 'emergency' or self.kind == kind:
            return []
        out = self.end('overridden by an emergency stop', now) if self.kind else []
        self.kind, self.reason, self.since = kind, text, now
        self._calm_since = None
        self.counts[kind] += 1
        return out + [StopChange(kind, 'begin', now, text)]

    def end(self, why: str, now: float) -> List[StopChange]:
        """End the standing stop for ``why``; return the change (none if no stop stands)."""
        if not self.kind:
            return []
        change = StopChange(self.kind, 'end', now, why, self.since)
        self.kind, self.reason, self.since = '', '', None
        return [change]

    def unsettled(self) -> None:
        """Start the calm over: the states just stopped being valid."""
        self._calm_since = None

    def calm(self, now: float, apart: bool, at_rest: bool, distance: float) -> List[StopChange]:
        """End a protective stop once the arms were ``apart`` and ``at_rest`` ``resume_after``.

        The bridge dropped the arms' moves when it held them, so nothing committed carries the
        arms back into the conflict; the job plans again from where they stand.

        :param distance: the arms' distance now, m (said in the end's text).
        """
        if self.kind != 'protective':
            return []
        if not (apart and at_rest):
            self._calm_since = None
        elif self._calm_since is None:
            self._calm_since = now
        elif now - self._calm_since >= self.resume_after:
            return self.end(f'valid states, arms at rest {distance:.3f} m apart for '
                            f'{now - self._calm_since:.2f} s', now)
        return []


class BreachForecast:
    """The first breach the arms' committed motion predicts, checked at every joint state.

    :param arms: the two arms; :param margin: m; :param dt: the physics step, s (the bridge's
        start rule, as :class:`~scara_collab.core.motion.Heard` applies it).
    """

    def __init__(self, arms: Sequence[ArmModel], margin: float, dt: float):
        """Nothing heard yet: both arms hold."""
        self.arms = tuple(arms)
        self.margin = float(margin)
        #: what the bridge runs, per arm, as heard (the committed-motion model's rules)
        self.heard = {arm.name: Heard(arm.name, dt=dt) for arm in self.arms}
        self.breach: Optional[float] = None  # sim s of the predicted first breach, or None
        self.again = True  # predict again at the next state
        self._started: Tuple = ()
        self._lines: list = []  # (move id, Timeline) per arm the breach was predicted from

    def on_trajectory(self, robot: str, move_id: str, stamp: float, t: ArrayLike,
                      q: ArrayLike, now: float, q_now: Optional[ArrayLike]) -> None:
        """Take a trajectory sent to ``robot``, as the bridge takes it (its status corrects it)."""
        self.heard[robot].trajectory(move_id, stamp, t, q, now, q_now)
        self.again = True

    def on_clock(self, robot: str, lag: float) -> None:
        """Take ``robot``'s trajectory clock: ``lag`` s behind sim time (speed scaling)."""
        heard = self.heard.get(robot)
        if heard is not None and heard.arm.lag != lag:
            heard.on_clock(lag)
            self.again = True

    def on_status(self, robot: str, state: str, move_id: str, now: float,
                  start: Optional[float], q_now: Optional[ArrayLike]) -> None:
        """Take the bridge's status of a move of ``robot`` (an unknown arm is ignored)."""
        heard = self.heard.get(robot)
        if heard is not None and heard.status(state, move_id, now, start, q_now):
            self.again = True

    def reason_to_stop(self, stamp: float, q: Sequence[np.ndarray], qd: Sequence[np.ndarray],
                       latency: float) -> Optional[str]:
        """Return why the arms must stop now to stay out of the margin, or None.

        :param q: both arms' joints measured at ``stamp``; :param qd: their velocities.
        :param latency: s from a state's measurement to the arms braking.
        """
        a, b = self.arms
        # a move counts from its start: until then a follower may still re-time it for a new
        # leader move (the priority rule); from then on the bridge runs it
        for arm in (a, b):
            self.heard[arm.name].arm.advance(stamp)
        running = [self.heard[arm.name].arm.running for arm in (a, b)]
        started = tuple(None if m is None else (m.id, m.start) for m in running)
        if self.again or started != self._started:
            self.again, self._started = False, started
            lines = [self.heard[arm.name].current(stamp, q[k]) for k, arm in enumerate((a, b))]
            self.breach = safety.first_breach(a, lines[0], b, lines[1], self.margin, stamp)
            self._lines = [('' if m is None else m.id, tl) for m, tl in zip(running, lines)]
        # predict only from what the arms do: a lost or late status must not fake a stop (the
        # measured distance against the margin still stands behind this)
        if any(np.max(np.abs(tl.at(stamp) - q[k])) > TRACKING for k, (_, tl)
               in enumerate(self._lines)):
            self.again = True
            return None
        stopping = max(safety.stopping_time(a, qd[0]), safety.stopping_time(b, qd[1]))
        if not safety.stop_due(stamp, self.breach, stopping, latency):
            return None
        moves = ', '.join(f'{arm.name} {m or "holding"} t={tl.start:.3f}..{tl.end:.3f} s'
                          for arm, (m, tl) in zip((a, b), self._lines))
        return (f'predicted: the commanded moves ({moves}) bring {a.name} and {b.name} within '
                f'{self.margin} m at t={self.breach:.3f} s, and braking takes '
                f'{stopping:.3f} s (+{latency:.3f} s latency) from t={stamp:.3f} s')
