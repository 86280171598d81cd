"""The collision monitor's standing stop, without ROS: begun, made an emergency, resumed, cleared.

One stop stands at a time, of one of two kinds:

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
from typing import Dict, List, Optional

KINDS = ('protective', 'emergency')


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
