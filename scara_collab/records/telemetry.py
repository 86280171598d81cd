"""The files of one run and the numbers behind its summary (numpy and the core, no rclpy).

:class:`RunLog` writes, in a run folder:

- ``timeseries.csv``: one row per joint state: ``t`` (sim s), the six joint positions (leader
  then follower, each ``joint_1, joint_2, gripper_joint``), both tool tips in ``world``
  (:func:`scara_collab.core.kinematics.fk`), the mirror error ``|p_follower - mirror(p_leader)|``
  (:func:`scara_collab.core.mirror.mirror_error`) and the arm-to-arm capsule surface distance
  (:func:`scara_collab.core.collision.arm_distance`), in metres;
- ``events.csv``: the conveyor events ``time, kind, item, class, robot``.

It also watches the joints' speeds between consecutive states: a joint faster than
:data:`OVERSPEED` times its velocity limit did something no admitted trajectory asks for (a
reference that jumped, a collision), so every such episode is kept (:attr:`RunLog.overspeed`).

States are buffered and computed in vectorised batches (at most ``batch`` rows, or whenever
:meth:`RunLog.flush` is called); every batch is written and flushed to disk at once, so a run
that is interrupted keeps every complete row it recorded. Events are flushed one by one.

Example::

    >>> import tempfile
    >>> from scara_collab.core.model import load_cell
    >>> folder = tempfile.TemporaryDirectory()         # a run folder, e.g. runs/<run>
    >>> log = RunLog(folder.name, load_cell())
    >>> log.add_state(0.01, [0.0, 1.57, 0.0], [0.0, -1.57, 0.0])   # mirrored poses
    >>> log.flush(); round(log.min_distance, 3), round(log.max_mirror_error, 6)
    (1.9, 0.0)
    >>> log.close(); folder.cleanup()
"""
import csv
import math
import os
from pathlib import Path
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from scara_collab.core.collision import arm_distance
from scara_collab.core.kinematics import fk
from scara_collab.core.mirror import mirror_error
from scara_collab.core.model import CellModel
from scara_collab.core.sorting import COUNTED

TIMESERIES = 'timeseries.csv'
EVENTS = 'events.csv'
EVENT_COLUMNS = ('time', 'kind', 'item', 'class', 'robot', 'cause')
#: a joint's measured speed above this many times its limit is an episode worth naming (the
#: trajectories are limited to 1.01 times it; measured between states 10 ms apart, runs that
#: track them stay below 1.1)
OVERSPEED = 1.2
#: overspeed episodes kept in full (all are counted)
OVERSPEED_KEPT = 20
MIRROR_ERROR = 'mirror_error_m'
ARM_DISTANCE = 'arm_distance_m'
try:
    _CLOCK_TICKS = float(os.sysconf('SC_CLK_TCK'))
except (AttributeError, ValueError, OSError):  # not POSIX: process_cpu_seconds gives None
    _CLOCK_TICKS = 100.0


class Event(NamedTuple):
    """One conveyor event: sim time (s), kind, item id, item class, robot ('' if none), cause."""

    time: float
    kind: str
    item: str
    cls: str
    robot: str
    cause: str = ''


def state_columns(cell: CellModel) -> List[str]:
    """Column names of ``timeseries.csv`` for ``cell`` (leader first).

    :param cell: the cell model.
    :return: ``t``, the six joint names, ``<robot>_tool_{x,y,z}`` for both arms,
        ``mirror_error_m``, ``arm_distance_m``.
    """
    cols = ['t']
    for arm in cell.arms:
        cols += list(arm.joint_names)
    for arm in cell.arms:
        cols += [f'{arm.name}_tool_{axis}' for axis in 'xyz']
    return cols + [MIRROR_ERROR, ARM_DISTANCE]


def state_metrics(cell: CellModel, q_leader, q_follower
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Tool tips, mirror error and arm distance of joint states (one or N at once).

    :param cell: the cell model (``cell.leader`` and ``cell.follower``).
    :param q_leader: (..., 3) leader joint states ``(theta1 rad, theta2 rad, d3 m)``.
    :param q_follower: (..., 3) follower joint states, same leading shape.
    :return: ``(p_leader (..., 3), p_follower (..., 3), mirror_error (...), distance (...))``,
        positions in ``world`` and lengths in m; the mirror error is the follower tool's
        distance from the mirror image of the leader tool, the distance is the smallest
        capsule surface distance between the arms (negative = overlap).
    """
    lead, foll = cell.leader, cell.follower
    q_leader = np.asarray(q_leader, dtype=float)
    q_follower = np.asarray(q_follower, dtype=float)
    p_lead = fk(lead, q_leader)
    p_foll = fk(foll, q_follower)
    error = mirror_error(lead, foll, p_lead, p_foll)
    distance = arm_distance(lead, q_leader, foll, q_follower)
    return p_lead, p_foll, error, distance


def parse_value(text: str) -> Union[None, bool, int, float, str]:
    """Typed value of a DiagnosticStatus key-value string.

    ``'true'``/``'false'`` -> bool, integers -> int, other numbers -> float (non-finite ->
    None, so it stays valid JSON), ``''``/``'none'``/``'null'`` -> None, anything else as is.
    """
    s = str(text).strip()
    low = s.lower()
    if low in ('true', 'false'):
        return low == 'true'
    if low in ('', 'none', 'null', 'n/a'):
        return None
    try:
        return int(s)
    except ValueError:
        pass
    try:
        v = float(s)
    except ValueError:
        return s
    return v if math.isfinite(v) else None


# t, joints, tool positions, mirror error, distance
_FORMAT = ['%.4f'] + ['%.6f'] * 6 + ['%.6f'] * 6 + ['%.9f', '%.6f']


class RunLog:
    """The CSV files of one run and the running aggregates of what they hold.

    :param directory: the run folder (created if needed).
    :param cell: the cell model (leader first).
    :param batch: pending joint states that trigger a write (rows are also written by
        :meth:`flush`).
    :param state_period: the publisher's joint state period, s; a step between consecutive
        stamps longer than 1.5 periods counts the states in between as missing.
    """

    def __init__(self, directory: Union[str, Path], cell: CellModel, batch: int = 200,
                 state_period: float = 0.01):
        """Create the folder, open the CSV files with their headers and zero the aggregates."""
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.cell = cell
        self.batch = max(1, int(batch))
        self.state_period = float(state_period)
        self.missing = 0            # joint states never heard (gaps in the stamps)
        self.largest_gap = 0.0      # s between consecutive recorded stamps, beyond one period
        self.columns = state_columns(cell)
        self.rows = 0
        self.t_first: Optional[float] = None
        self.t_last: Optional[float] = None
        self.min_distance = math.inf
        self.min_distance_time: Optional[float] = None
        self.max_mirror_error = 0.0
        self.max_mirror_error_time: Optional[float] = None
        self.events: List[Event] = []
        #: ``{time, robot, joint, speed, limit}`` of the first :data:`OVERSPEED_KEPT` episodes
        #: of a joint above :data:`OVERSPEED` times its limit (when each began, its peak speed)
        self.overspeed: List[Dict[str, object]] = []
        self.overspeed_count = 0
        self.max_speed_ratio = 0.0  # the fastest any joint went, as a share of its limit
        self._limits = np.concatenate([a.max_velocity for a in cell.arms])
        self._joints = [(a.name, k + 1) for a in cell.arms for k in range(3)]
        self._last: Optional[Tuple[float, np.ndarray]] = None  # the last state written (t, q)
        self._episode_end: Dict[int, float] = {}  # joint index -> last overspeed sample, s
        self.closed = False
        self._t: List[float] = []
        self._q: List[np.ndarray] = []
        self._ts = open(self.directory / TIMESERIES, 'w', newline='', encoding='utf-8')
        self._ts.write(','.join(self.columns) + '\n')
        self._ts.flush()
        self._ev = open(self.directory / EVENTS, 'w', newline='', encoding='utf-8')
        self._ev_csv = csv.writer(self._ev, lineterminator='\n')
        self._ev_csv.writerow(EVENT_COLUMNS)
        self._ev.flush()

    # --- input -----------------------------------------------------------------------------
    def add_state(self, t: float, q_leader: Sequence[float], q_follower: Sequence[float]) -> None:
        """Queue one joint state (sim time ``t`` s); written at the next batch or flush."""
        if self.closed:
            return
        self._t.append(float(t))
        self._q.append(np.concatenate((np.asarray(q_leader, dtype=float).reshape(3),
                                       np.asarray(q_follower, dtype=float).reshape(3))))
        if self.t_first is None:
            self.t_first = float(t)
        self.t_last = float(t)
        if len(self._t) >= self.batch:
            self.flush()

    def add_event(self, t: float, kind: str, item='', cls: str = '', robot: str = '',
                  cause: str = '') -> None:
        """Record one conveyor event and flush it to ``events.csv``."""
        if self.closed:
            return
        ev = Event(float(t), str(kind), str(item), str(cls), str(robot), str(cause))
        self.events.append(ev)
        self._ev_csv.writerow([f'{ev.time:.3f}', ev.kind, ev.item, ev.cls, ev.robot, ev.cause])
        self._ev.flush()

    def flush(self) -> None:
        """Compute the queued rows, append them to ``timeseries.csv`` and flush the files."""
        if self.closed:
            return
        if self._t:
            t = np.asarray(self._t)
            q = np.vstack(self._q)
            self._t, self._q = [], []
            p_lead, p_foll, error, dist = state_metrics(self.cell, q[:, :3], q[:, 3:])
            np.savetxt(self._ts, np.column_stack((t, q, p_lead, p_foll, error, dist)),
                       fmt=_FORMAT, delimiter=',')
            self.rows += t.size
            steps = np.diff(t if self._last is None else np.concatenate(([self._last[0]], t)))
            late = steps > 1.5 * self.state_period
            if np.any(late):
                self.missing += int(np.sum(np.round(steps[late] / self.state_period) - 1))
                self.largest_gap = max(self.largest_gap, float(steps[late].max()))
            self._watch_speed(t, q)
            k = int(np.argmin(dist))
            if dist[k] < self.min_distance:
                self.min_distance, self.min_distance_time = float(dist[k]), float(t[k])
            k = int(np.argmax(error))
            if error[k] > self.max_mirror_error or self.max_mirror_error_time is None:
                self.max_mirror_error, self.max_mirror_error_time = float(error[k]), float(t[k])
        self._ts.flush()
        self._ev.flush()

    def _watch_speed(self, t: np.ndarray, q: np.ndarray) -> None:
        """Take the joint speeds between consecutive states (a gap is not a speed)."""
        if self._last is not None:
            t = np.concatenate(([self._last[0]], t))
            q = np.vstack([self._last[1], q])
        self._last = (float(t[-1]), q[-1].copy())
        if t.size < 2:
            return
        dt = np.diff(t)
        close = (dt > 0) & (dt <= 1.5 * self.state_period)
        ratio = np.abs(np.diff(q, axis=0)) / np.where(close, dt, 1.0)[:, None] / self._limits
        ratio[~close] = 0.0
        self.max_speed_ratio = max(self.max_speed_ratio, float(ratio.max()))
        for i, j in np.argwhere(ratio > OVERSPEED):
            at, r = float(t[i + 1]), float(ratio[i, j])
            episode = self._episode_end.get(int(j))
            self._episode_end[int(j)] = at
            robot, joint = self._joints[j]
            row = {'time': round(at, 3), 'robot': robot, 'joint': joint,
                   'speed': round(r * float(self._limits[j]), 3),
                   'limit': float(self._limits[j])}
            if episode is None or at - episode > 0.1:  # a new episode
                self.overspeed_count += 1
                if len(self.overspeed) < OVERSPEED_KEPT:
                    self.overspeed.append(row)
            else:  # the same episode: keep its fastest sample
                same = [e for e in self.overspeed if e['robot'] == robot and e['joint'] == joint]
                if same and same[-1]['speed'] < row['speed']:
                    same[-1].update(speed=row['speed'])

    def close(self) -> None:
        """Write what is queued and close the files (idempotent)."""
        if self.closed:
            return
        self.flush()
        self._ts.close()
        self._ev.close()
        self.closed = True

    # --- numbers ---------------------------------------------------------------------------
    def event_counts(self, t_start: float = -math.inf, t_end: float = math.inf) -> Dict[str, int]:
        """Events per kind with ``t_start <= time <= t_end``; every kind of :data:`COUNTED`."""
        counts = {k: 0 for k in COUNTED}
        for ev in self.events:
            if t_start <= ev.time <= t_end:
                counts[ev.kind] = counts.get(ev.kind, 0) + 1
        return counts


def process_cpu_seconds(pid: int) -> Optional[float]:
    """CPU seconds (user + system) a process has used so far, from ``/proc/<pid>/stat``.

    ``None`` where there is no ``/proc`` (not Linux) or the process is gone.
    """
    try:
        with open(f'/proc/{int(pid)}/stat', encoding='ascii') as f:
            fields = f.read().rsplit(')', 1)[1].split()  # the name in () may hold spaces
    except (OSError, IndexError):
        return None
    # fields[0] is field 3 (state); utime and stime are fields 14 and 15
    return (int(fields[11]) + int(fields[12])) / _CLOCK_TICKS


class CpuMeter:
    """CPU seconds per sim second of each process over a window of sim time.

    The launcher marks the job's start and end; the cost of the graph is what each process
    used in between divided by the sim time that passed (so it does not depend on how fast
    the machine ran the graph, and it adds up to the cores the graph needs at 1x).
    """

    def __init__(self):
        """Start with no window marked."""
        self._start: Dict[str, Tuple[float, float]] = {}
        self.result: Dict[str, float] = {}

    @property
    def marked(self) -> bool:
        """Whether the window has started."""
        return bool(self._start)

    def mark(self, cpu: Dict[str, Optional[float]], sim_time: float) -> None:
        """Start the window: ``cpu`` maps a process name to its CPU seconds so far."""
        self._start = {k: (v, sim_time) for k, v in cpu.items() if v is not None}

    def close(self, cpu: Dict[str, Optional[float]], sim_time: float) -> Dict[str, float]:
        """End the window; return ``{name: CPU s per sim s}`` plus ``total`` (rounded)."""
        out: Dict[str, float] = {}
        for name, used in cpu.items():
            if used is None or name not in self._start:
                continue
            c0, t0 = self._start[name]
            if sim_time > t0:
                out[name] = round((used - c0) / (sim_time - t0), 4)
        if out:
            out['total'] = round(sum(out.values()), 4)
        self.result = out
        return out
