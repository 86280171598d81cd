"""The run's stops, as the summary counts them: protective and emergency, cause, cost, standing.

No rclpy here. Three sources feed one :class:`StopLog` (the run recorder converts the messages):

- the collision monitor's stop events (``/collision_monitor/stops``,
  :class:`scara_collab.nodes.protocol.StopEvent`): each stop's begin and end, the one source of
  the lists;
- its newest status (``/collision_monitor/status``, ``MonitorStatus.stopped`` and ``kind``):
  a stop it still reports at the end stands, even if its begin was lost; a status newer than
  a begin that reports no stop of that kind ends it (its end was lost);
- the latched ``/emergency_stop`` (the bridge obeys it, whoever publishes it): a hold seen
  there that no emergency stop event covers is listed too, so nothing the bridge obeyed is
  missing from the summary.

A stop *stands* when no end of it was heard (and no newer status says it is over). Its cost,
``lost``, is the sim time from its begin to its end, or to the end of the run if it stands.
Stops that begin after the end of the run (while the graph shuts down) are not the run's.

>>> log = StopLog()
>>> log.event('protective', 'begin', 10.0, 'predicted breach')
>>> log.event('protective', 'end', 10.75, 'arms at rest', since=10.0)
>>> log.event('emergency', 'begin', 20.0, 'margin broken')
>>> stops = log.summary(30.0)
>>> [(s['time'], s['lost'], s['standing']) for s in stops['protective_stops']]
[(10.0, 0.75, False)]
>>> [(s['cause'], s['lost'], s['standing']) for s in stops['emergency_stops']]
[('margin broken', 10.0, True)]
"""
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

KINDS = ('protective', 'emergency')  # as scara_collab.nodes.protocol.STOP_KINDS
#: sim s: a hold on ``/emergency_stop`` this close to an emergency stop event is that stop
#: (the recorder stamps the topic's change when it hears it, the monitor when it stops)
SAME_STOP = 1.0
EPS = 1e-6


@dataclass
class Stop:
    """One stop: its kind, when it began (sim s) and why; when and why it ended."""

    kind: str
    time: float
    cause: str
    end: Optional[float] = None
    released: str = ''
    source: str = 'stop event'

    def values(self, t_end: float) -> Dict[str, object]:
        """Return the stop as the summary lists it; ``t_end``: the end of the run, sim s."""
        standing = self.end is None
        lost = (t_end if standing else self.end) - self.time
        return {'time': self.time, 'cause': self.cause, 'lost': round(max(0.0, lost), 6),
                'standing': standing, 'end': self.end, 'released': self.released,
                'source': self.source}


class StopLog:
    """Every stop of a run from its three sources; see the module docstring."""

    def __init__(self):
        """Start with no stop heard."""
        self.stops: List[Stop] = []
        self.held: List[List[Optional[float]]] = []  # /emergency_stop holds: [on, off or None]
        self.status: Optional[Tuple[float, str, str]] = None  # newest (time, kind, reason)
        self.status_since: Optional[float] = None  # first time it reported that stop

    def _open(self, kind: str, since: Optional[float] = None) -> Optional[Stop]:
        """Return the newest standing stop of ``kind`` (that began at ``since``, if given)."""
        for stop in reversed(self.stops):
            if stop.kind == kind and stop.end is None and (
                    since is None or abs(stop.time - since) < EPS):
                return stop
        return None

    def event(self, kind: str, state: str, time: float, cause: str,
              since: Optional[float] = None) -> None:
        """Take a stop event: ``state`` ``begin`` or ``end`` of a ``kind`` stop at ``time``.

        :param since: for an end, when the stop began (sim s), if the event says.
        """
        if kind not in KINDS:
            raise ValueError(f'stop kind {kind!r} is not one of {KINDS}')
        if state == 'begin':
            if not any(s.kind == kind and abs(s.time - time) < EPS for s in self.stops):
                self.stops.append(Stop(kind, float(time), cause))  # (a repeat is ignored)
            return
        if state != 'end':
            raise ValueError(f'stop state {state!r} is not begin or end')
        stop = self._open(kind, since) or self._open(kind)
        if stop is None:  # its begin was not heard
            begin = float(time if since is None else since)
            if any(s.kind == kind and abs(s.time - begin) < EPS for s in self.stops):
                return  # a repeated end
            stop = Stop(kind, begin, f'(begin not heard; released: {cause})')
            self.stops.append(stop)
        stop.end, stop.released = float(time), cause

    def request(self, on: bool, time: float) -> None:
        """Take the latched ``/emergency_stop`` at ``time``: a change begins or ends a hold."""
        standing = bool(self.held) and self.held[-1][1] is None
        if on and not standing:
            self.held.append([float(time), None])
        elif not on and standing:
            self.held[-1][1] = float(time)

    def monitor(self, time: float, stopped: bool, kind: str, reason: str) -> None:
        """Take the collision monitor's newest status (``kind`` '' means emergency)."""
        if not stopped:
            self.status, self.status_since = (float(time), '', ''), None
            return
        kind = kind or 'emergency'
        if self.status is None or self.status[1] != kind or self.status[2] != reason:
            self.status_since = float(time)
        self.status = (float(time), kind, reason)

    def summary(self, t_end: float) -> Dict[str, List[Dict[str, object]]]:
        """Return ``protective_stops`` and ``emergency_stops`` of a run that ended at ``t_end``.

        Each a list, oldest first, of ``{time, cause, lost, standing, end, released,
        source}`` (sim s; ``lost`` counted to ``t_end`` for a stop that stands).
        """
        stops = [Stop(**vars(s)) for s in self.stops if s.time <= t_end + EPS]
        if self.status is not None:
            t_status, kind, reason = self.status
            for stop in stops:  # a newer status reporting no such stop: its end was lost
                if stop.end is None and stop.time < t_status - EPS and stop.kind != kind:
                    stop.end, stop.released = t_status, '(end not heard; the monitor ' \
                        'reports no such stop)'
            since = self.status_since if self.status_since is not None else t_status
            known = any(s.kind == kind and (s.end is None or s.end >= t_status - EPS)
                        for s in stops)  # standing, or ended after the status was sent
            if kind and since <= t_end + EPS and not known:
                stops.append(Stop(kind, since, reason, source='collision_monitor status'))
        for on, off in self.held:
            if on > t_end + EPS:
                continue
            covered = any(s.kind == 'emergency' and s.time - SAME_STOP <= on
                          and (s.end is None or on <= s.end + SAME_STOP) for s in stops)
            if not covered:
                stops.append(Stop('emergency', on, 'held on /emergency_stop (no stop event '
                                  'heard)', off, '' if off is None else '/emergency_stop '
                                  'released', source='/emergency_stop'))
        stops.sort(key=lambda s: s.time)
        return {f'{kind}_stops': [s.values(t_end) for s in stops if s.kind == kind]
                for kind in KINDS}
