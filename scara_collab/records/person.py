"""What a run with a person in it records: the summary's ``person`` block and its two CSV files.

No rclpy here. :class:`PersonLog` is fed by the run recorder (it converts the messages) from
four sources, one per kind of figure:

=================================  ====================================================
figures                            source
=================================  ====================================================
intrusions, min_separation_m,      ``/person/truth`` (:class:`~scara_collab.nodes.protocol.
min_ssm_margin_m, contacts_...     PersonTruth`, the bridge's ground truth)
protective_stops, stop_seconds,    ``/separation_monitor/status`` (:class:`~scara_collab.
slowed_seconds, slowdowns,         nodes.protocol.SeparationStatus`, the monitor's decisions)
resume_seconds_max, faults
false_slowdowns                    the monitor's slow-downs against the truth's presence
missed_due_to_person               ``/automation_manager/stats`` (``JobStats``)
lag_max_s, held_back (per arm)     ``/<robot>/trajectory_clock`` (``TrajectoryClock``)
=================================  ====================================================

**An arm's state**, per monitor status: *stopped* while the monitor stops it (its ``stop``
flag), gives it the factor 0, or has a fault (a fault stops every arm); *slowed* while its
factor is below 1 and above 0; else at *full speed*. A *protective stop* is a rising edge of
stopped (counted per arm, summed); ``stop_seconds`` and ``slowed_seconds`` are the sim seconds
*any* arm was stopped, or slowed (a status's state holds until the next one, the last until
the end of the run). A *slow-down* is an episode of an arm below full speed (slowed or
stopped) from the status that lowered it to the one that gave it full speed again; it is
*false* if the truth says no person was in the cell at any time during it (ghost points: a
scanner artefact) and no fault began it (faults are counted apart, ``fault_stops``).

**Resume**: in each slow-down that ends, the arm is *held* at each status whose ``margin`` is
below 0 (the person within its protective separation ``S_p`` as the monitor sees it), that
stops it or that has a fault; the person is *clear* at the first status after the last held
one. ``resume_seconds`` is the sim time from clear to full speed again; the worst is
``resume_seconds_max``.

**The start-up**: the monitor starts every arm at the factor 0 and raises it once the empty
cell's contour is taught (:mod:`scara_collab.core.separation_monitor`). The statuses until it
first gives every arm full speed without a fault are the start-up (``startup_seconds``), not
counted as stops or slow-downs, unless a person interrupts it first: a factor that falls or an
arm stopped without a fault ends it there, and what that status shows counts.

From the truth (each arm as the bridge measures it): an *intrusion* is a rising edge of
``present`` (the person entered the cell); ``min_separation_m`` and ``min_ssm_margin_m`` are
the least separation and the least ``S - S_p`` of an arm while that arm moved; a contact while
moving is a rising edge of (``contact`` and ``moving``) of an arm, summed.

The CSV files (written in batches, and on :meth:`PersonLog.flush`): ``separation.csv``, one row
per monitor status (``t``, ``fault``, per arm ``<robot>_S_m``, ``<robot>_Sp_m`` = separation
minus margin, ``<robot>_scale``, ``<robot>_stopped`` (1: the arm's state is stopped);
``inf`` where no person is seen), and
``person_truth.csv``, one row per truth (``t``, ``present``, per arm ``<robot>_S_m``,
``<robot>_margin_m``, ``<robot>_moving``, ``<robot>_contact``).

>>> import tempfile
>>> folder = tempfile.TemporaryDirectory()
>>> log = PersonLog(folder.name, 'middle', ['left'])
>>> log.add_status(0.0, {'left': 1.0}, {}, {}, {})                  # start-up over
>>> log.add_truth(1.0, True, {'left': 1.6}, {'left': 0.4}, {'left': True}, {})
>>> log.add_status(1.0, {'left': 0.5}, {}, {'left': 1.6}, {'left': -0.2})
>>> log.add_status(2.0, {'left': 0.5}, {}, {'left': 1.9}, {'left': 0.1})
>>> log.add_status(3.0, {'left': 1.0}, {}, {'left': 2.5}, {'left': 0.7})
>>> block = log.summary(10.0)
>>> block['intrusions'], block['slowdowns'], block['slowed_seconds'], block['resume_seconds_max']
(1, 1, 2.0, 1.0)
>>> block['min_separation_m'], block['min_ssm_margin_m'], block['false_slowdowns']
(1.6, 0.4, 0)
>>> log.close(); folder.cleanup()
"""
import csv
from dataclasses import dataclass
import math
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Union

SEPARATION = 'separation.csv'
TRUTH = 'person_truth.csv'
#: faults listed in the block (all are counted)
FAULTS_KEPT = 10
#: a factor this close to 1 is full speed
FULL = 1.0 - 1e-9
FULL_SPEED, SLOWED, STOPPED = 'full', 'slowed', 'stopped'
SOURCE = ('/person/truth (intrusions, separations, margins, contacts); '
          '/separation_monitor/status (stops, slow-downs, resume, faults); '
          '/automation_manager/stats (missed_due_to_person); '
          '/<robot>/trajectory_clock (lag, held back)')


def arm_state(scale: float, stop: bool, fault: str) -> str:
    """Return an arm's state in a monitor status: stopped, slowed or full speed.

    >>> arm_state(1.0, False, ''), arm_state(0.4, False, ''), arm_state(0.0, False, '')
    ('full', 'slowed', 'stopped')
    >>> arm_state(1.0, True, ''), arm_state(1.0, False, 'scanner_a: no scan yet')
    ('stopped', 'stopped')
    """
    if fault or stop or not scale > 0.0:
        return STOPPED
    return FULL_SPEED if scale >= FULL else SLOWED


def _least(current: Optional[Dict], value: float, t: float, robot: str) -> Optional[Dict]:
    """Return ``{value, time, robot}`` of the smaller of ``current`` and ``value`` (finite)."""
    if not math.isfinite(value) or (current is not None and value >= current['value']):
        return current
    return {'value': float(value), 'time': float(t), 'robot': robot}


@dataclass
class Episode:
    """One slow-down of an arm: from ``start`` to ``end`` (None: to the end of the run), sim s.

    :ivar fault: a fault began it.
    :ivar held: the last status in it that held the arm (margin < 0, a stop, a fault).
    :ivar clear: the first status after ``held`` (None: none yet).
    """

    start: float
    fault: bool
    end: Optional[float] = None
    held: Optional[float] = None
    clear: Optional[float] = None

    @property
    def resume(self) -> Optional[float]:
        """Return the sim s from clear to full speed (None: not ended, or never held)."""
        if self.end is None or self.held is None:
            return None
        return self.end - (self.clear if self.clear is not None else self.end)


class ArmWatch:
    """One arm's figures: the monitor's states and slow-downs, the truth, its clock."""

    def __init__(self, robot: str):
        """Start at full speed, nothing heard."""
        self.robot = robot
        self.state = FULL_SPEED
        self.stops = 0
        self.stop_seconds = 0.0
        self.slowed_seconds = 0.0
        self.episodes: List[Episode] = []
        self.min_separation: Optional[Dict] = None
        self.min_margin: Optional[Dict] = None
        self.contact = False
        self.contact_moving = False
        self.contacts = 0
        self.contacts_while_moving = 0
        self.first_contact_while_moving: Optional[float] = None
        self.lag_max = 0.0
        self.held_back = 0
        self._held_back = False

    @property
    def episode(self) -> Optional[Episode]:
        """Return the slow-down going on, or None."""
        if self.episodes and self.episodes[-1].end is None:
            return self.episodes[-1]
        return None

    def advance(self, dt: float) -> None:
        """Count ``dt`` sim s of the current state."""
        if self.state == STOPPED:
            self.stop_seconds += dt
        elif self.state == SLOWED:
            self.slowed_seconds += dt

    def take(self, t: float, state: str, held: bool, fault: bool) -> None:
        """Take the arm's state in a monitor status at ``t`` (``held``: it holds the arm)."""
        if state == STOPPED and self.state != STOPPED:
            self.stops += 1
        episode = self.episode
        if state != FULL_SPEED and episode is None:
            episode = Episode(t, fault)
            self.episodes.append(episode)
        if episode is not None:
            if held:
                episode.held, episode.clear = t, None
            elif episode.held is not None and episode.clear is None:
                episode.clear = t
            if state == FULL_SPEED:
                episode.end = t
        self.state = state

    def truth(self, t: float, separation: float, margin: float, moving: bool,
              contact: bool) -> None:
        """Take the truth about this arm at ``t``."""
        if moving:
            self.min_separation = _least(self.min_separation, separation, t, self.robot)
            self.min_margin = _least(self.min_margin, margin, t, self.robot)
        both = contact and moving
        if contact and not self.contact:
            self.contacts += 1
        if both and not self.contact_moving:
            self.contacts_while_moving += 1
            if self.first_contact_while_moving is None:
                self.first_contact_while_moving = float(t)
        self.contact, self.contact_moving = contact, both

    def clock(self, lag: float, held_back: bool) -> None:
        """Take the arm's trajectory clock."""
        if math.isfinite(lag):
            self.lag_max = max(self.lag_max, float(lag))
        if held_back and not self._held_back:
            self.held_back += 1
        self._held_back = held_back


def _overlaps(start: float, end: float, intervals: Sequence[Sequence[Optional[float]]]) -> bool:
    """Return True if ``[start, end]`` meets an interval ``[on, off]`` (off None: open)."""
    return any(on <= end and (off is None or off >= start) for on, off in intervals)


def _value(least: Optional[Dict]):
    return None if least is None else least['value']


class PersonLog:
    """The figures and files of a run with a person (see the module docstring).

    :param directory: the run folder (it exists).
    :param scenario: the person scenario's name (or its file).
    :param robots: the arms, leader first.
    :param batch: rows kept before they are written.
    """

    def __init__(self, directory: Union[str, Path], scenario: str, robots: Sequence[str],
                 batch: int = 200):
        """Open both CSV files; nothing heard yet."""
        self.directory = Path(directory)
        self.scenario = scenario
        self.robots = list(robots)
        self.batch = batch
        self.arms = {r: ArmWatch(r) for r in self.robots}
        self.missed_due_to_person: Optional[int] = None
        # the truth
        self.truth_messages = 0
        self.present = False
        self.presence: List[List[Optional[float]]] = []  # [entered, left or None]
        # the monitor
        self.status_messages = 0
        self.startup_end: Optional[float] = None
        self.first_status: Optional[float] = None
        self.last_status: Optional[float] = None
        self.stop_seconds = 0.0     # any arm stopped
        self.slowed_seconds = 0.0   # any arm slowed
        self.faults: List[Dict[str, object]] = []  # after the start-up: {time, fault, end}
        self.fault_count = 0
        self.fault = ''                      # the newest status's
        self.fault_since: Optional[float] = None
        self._scales: Dict[str, float] = {}
        self.closed = False
        self._files = {}
        self._rows: Dict[str, List[List[str]]] = {}
        for name, columns in ((SEPARATION, self._status_columns()),
                              (TRUTH, self._truth_columns())):
            f = open(self.directory / name, 'w', encoding='utf-8', newline='')
            writer = csv.writer(f, lineterminator='\n')
            writer.writerow(columns)
            f.flush()
            self._files[name] = (f, writer)
            self._rows[name] = []

    def _status_columns(self) -> List[str]:
        return ['t', 'fault'] + [f'{r}_{c}' for r in self.robots
                                 for c in ('S_m', 'Sp_m', 'scale', 'stopped')]

    def _truth_columns(self) -> List[str]:
        return ['t', 'present'] + [f'{r}_{c}' for r in self.robots
                                   for c in ('S_m', 'margin_m', 'moving', 'contact')]

    def _row(self, name: str, row: List[str]) -> None:
        if self.closed:
            return
        rows = self._rows[name]
        rows.append(row)
        if len(rows) >= self.batch:
            self._write(name)

    def _write(self, name: str) -> None:
        f, writer = self._files[name]
        rows = self._rows[name]
        if rows:
            writer.writerows(rows)
            rows.clear()
            f.flush()

    # --- input -----------------------------------------------------------------------------
    def add_truth(self, t: float, present: bool, separation: Mapping[str, float],
                  margin: Mapping[str, float], moving: Mapping[str, bool],
                  contact: Mapping[str, bool]) -> None:
        """Take a ``PersonTruth`` at sim time ``t`` (per arm: m, m, flags)."""
        self.truth_messages += 1
        if present and not self.present:
            self.presence.append([float(t), None])
        elif not present and self.present and self.presence:
            self.presence[-1][1] = float(t)
        self.present = bool(present)
        row = [f'{t:.4f}', str(int(bool(present)))]
        for r in self.robots:
            s = float(separation.get(r, math.inf))
            m = float(margin.get(r, math.inf))
            mv, c = bool(moving.get(r, False)), bool(contact.get(r, False))
            self.arms[r].truth(t, s, m, mv, c)
            row += [f'{s:.6f}', f'{m:.6f}', str(int(mv)), str(int(c))]
        self._row(TRUTH, row)

    def add_status(self, t: float, scale: Mapping[str, float], stop: Mapping[str, bool],
                   separation: Mapping[str, float], margin: Mapping[str, float],
                   fault: str = '') -> None:
        """Take a ``SeparationStatus`` at sim time ``t``; one older than the last is ignored.

        An arm the status leaves out has the factor 0 (the monitor stops an arm it has no
        state of).
        """
        if self.last_status is not None and t < self.last_status:
            return
        self.status_messages += 1
        if self.first_status is None:
            self.first_status = float(t)
        self._advance(t)
        if fault and not self.fault:
            self.fault_since = float(t)
        scales = {r: float(scale.get(r, 0.0)) for r in self.robots}
        states = {r: arm_state(scales[r], bool(stop.get(r, False)), fault) for r in self.robots}
        if self.startup_end is None and (
                (not fault and all(s == FULL_SPEED for s in states.values()))
                or any(scales[r] < self._scales.get(r, 0.0) for r in self.robots)
                or (not fault and any(stop.get(r, False) for r in self.robots))):
            self.startup_end = float(t)
        if self.startup_end is not None:
            if fault and not self.fault:
                self.fault_count += 1
                if len(self.faults) < FAULTS_KEPT:
                    self.faults.append({'time': float(t), 'fault': fault, 'end': None})
            elif not fault and self.fault and self.faults and self.faults[-1]['end'] is None:
                self.faults[-1]['end'] = float(t)
            for r in self.robots:
                m = float(margin.get(r, math.inf))
                held = bool(fault) or bool(stop.get(r, False)) or m < 0.0
                self.arms[r].take(t, states[r], held, bool(fault))
        self.fault = fault
        if not fault:
            self.fault_since = None
        self._scales = scales
        self.last_status = float(t)
        row = [f'{t:.4f}', fault]
        for r in self.robots:
            s = float(separation.get(r, math.inf))
            m = float(margin.get(r, math.inf))
            sp = s - m if math.isfinite(s) and math.isfinite(m) else math.inf
            row += [f'{s:.6f}', f'{sp:.6f}', f'{scales[r]:.6f}', str(int(states[r] == STOPPED))]
        self._row(SEPARATION, row)

    def _advance(self, t: float) -> None:
        """Count the time from the last status to ``t`` in the states it gave (after start-up)."""
        if self.startup_end is None or self.last_status is None or t <= self.last_status:
            return
        dt = t - self.last_status
        states = [a.state for a in self.arms.values()]
        if STOPPED in states:
            self.stop_seconds += dt
        if SLOWED in states:
            self.slowed_seconds += dt
        for arm in self.arms.values():
            arm.advance(dt)

    def add_clock(self, robot: str, lag: float, held_back: bool) -> None:
        """Take an arm's ``TrajectoryClock`` (its lag, s; held back by its path-keeping stop)."""
        if robot in self.arms:
            self.arms[robot].clock(lag, held_back)

    def add_stats(self, missed_due_to_person: int) -> None:
        """Take the job's ``missed_due_to_person`` (``JobStats``)."""
        self.missed_due_to_person = int(missed_due_to_person)

    # --- output ----------------------------------------------------------------------------
    def flush(self) -> None:
        """Write the rows kept."""
        if not self.closed:
            for name in self._files:
                self._write(name)

    def close(self) -> None:
        """Write the rows kept and close the files (idempotent)."""
        if self.closed:
            return
        self.flush()
        for f, _ in self._files.values():
            f.close()
        self.closed = True

    def summary(self, t_end: float) -> Dict[str, object]:
        """Return the ``person`` block of a run that ended at ``t_end`` (sim s).

        The states the newest status gave hold until ``t_end``; a slow-down still going on
        ends there for the false slow-downs and has no resume time.
        """
        tail = max(0.0, t_end - self.last_status) if (
            self.last_status is not None and self.startup_end is not None) else 0.0
        states = [a.state for a in self.arms.values()]
        arms = {}
        for r, a in self.arms.items():
            false = [e for e in a.episodes if not e.fault and not _overlaps(
                e.start, t_end if e.end is None else e.end, self.presence)]
            resumes = [e.resume for e in a.episodes if e.resume is not None]
            arms[r] = {
                'protective_stops': a.stops,
                'stop_seconds': a.stop_seconds + (tail if a.state == STOPPED else 0.0),
                'slowed_seconds': a.slowed_seconds + (tail if a.state == SLOWED else 0.0),
                'slowdowns': len(a.episodes),
                'false_slowdowns': len(false) if self.truth_messages else None,
                'resume_seconds_max': max(resumes) if resumes else None,
                'min_separation_m': _value(a.min_separation),
                'min_ssm_margin_m': _value(a.min_margin),
                'contacts': a.contacts,
                'contacts_while_moving': a.contacts_while_moving,
                'lag_max_s': a.lag_max,
                'held_back': a.held_back}
        least_sep = least_margin = None
        for a in self.arms.values():
            if a.min_separation is not None:
                least_sep = _least(least_sep, a.min_separation['value'],
                                   a.min_separation['time'], a.robot)
            if a.min_margin is not None:
                least_margin = _least(least_margin, a.min_margin['value'], a.min_margin['time'],
                                      a.robot)
        touched = [(a.first_contact_while_moving, r) for r, a in self.arms.items()
                   if a.first_contact_while_moving is not None]
        first_touch = min(touched) if touched else None
        resumes = [v['resume_seconds_max'] for v in arms.values()
                   if v['resume_seconds_max'] is not None]
        present = sum(min(t_end, math.inf if off is None else off) - on
                      for on, off in self.presence if on <= t_end)
        startup = None
        if self.first_status is not None:
            startup = (self.startup_end if self.startup_end is not None else t_end) \
                - self.first_status
        truth = self.truth_messages > 0
        return {
            'scenario': self.scenario,
            'intrusions': len(self.presence) if truth else None,
            'present_seconds': present if truth else None,
            'protective_stops': sum(a.stops for a in self.arms.values()),
            'stop_seconds': self.stop_seconds + (tail if STOPPED in states else 0.0),
            'slowed_seconds': self.slowed_seconds + (tail if SLOWED in states else 0.0),
            'slowdowns': sum(v['slowdowns'] for v in arms.values()),
            'false_slowdowns': sum(v['false_slowdowns'] for v in arms.values())
            if truth else None,
            'resume_seconds_max': max(resumes) if resumes else None,
            'min_separation_m': _value(least_sep),
            'min_separation_time': None if least_sep is None else least_sep['time'],
            'min_separation_robot': None if least_sep is None else least_sep['robot'],
            'min_ssm_margin_m': _value(least_margin),
            'min_ssm_margin_time': None if least_margin is None else least_margin['time'],
            'min_ssm_margin_robot': None if least_margin is None else least_margin['robot'],
            'contacts_while_moving': sum(a.contacts_while_moving for a in self.arms.values()),
            'first_contact_while_moving': None if first_touch is None else {
                'time': first_touch[0], 'robot': first_touch[1]},
            'contacts': sum(a.contacts for a in self.arms.values()),
            'missed_due_to_person': self.missed_due_to_person,
            'fault_stops': self.fault_count,
            'faults': [dict(f) for f in self.faults],
            'fault_at_end': self.fault,
            'fault_since': self.fault_since,
            'startup_seconds': startup,
            'truth_messages': self.truth_messages,
            'monitor_statuses': self.status_messages,
            'arms': arms,
            'source': SOURCE,
        }
