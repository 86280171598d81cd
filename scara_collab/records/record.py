"""The record of one run: its files, the figures the graph reported, the job window, the summary.

No rclpy here: :class:`RunRecord` is fed by the ``run_recorder`` node
(:class:`scara_collab.nodes.recorder.RunRecorder`, which is a RunRecord too), one source per
figure of the summary:

================================  =====================================================
summary field                     source
================================  =====================================================
sorted, missed, dropped, ...      the bridge's ``/conveyor/events`` inside the job window
items_per_minute                  those counts over the window
                                  (:func:`scara_collab.core.job.items_per_minute`)
min_separation_m                  ``/collision_monitor/status`` (its minimum)
mirror_error_max_m                ``/replication_manager/status`` (in-step moves)
job (give-ups, retries, phases)   ``/automation_manager/stats``
protective_stops, emergency_stops ``/collision_monitor/stops``, its status and the latched
                                  ``/emergency_stop`` (:mod:`scara_collab.records.stops`)
foreign_clocks, second_graphs     the graph itself, looked at once a wall second
                                  (:mod:`scara_collab.records.graph_watch`)
silences                          the launcher's lockstep watch
                                  (:meth:`scara_collab.run.liveness.Liveness.summary`)
person (a run with a person)      ``/person/truth``, ``/separation_monitor/status``,
                                  ``/<robot>/trajectory_clock``, the job's stats
                                  (:mod:`scara_collab.records.person`)
exit_code, exit_reason, problems  all of the above (:mod:`scara_collab.records.verdict`)
================================  =====================================================

The joint states and events go to the CSV files and their numbers
(:class:`scara_collab.records.telemetry.RunLog`); the summary and the plots are written by
:mod:`scara_collab.records.report` when the run ends (:meth:`RunRecord.finish`), or with
``interrupted: true`` when the record is closed before that (:meth:`RunRecord.close`).

The launcher tells the record when the job window starts (:meth:`RunRecord.start_job`) and
ends (:meth:`RunRecord.freeze`); ``sim_seconds``, ``wall_seconds``, the real-time factor and
the item counts of the summary refer to that window, and a stop that begins after it is not
the run's. The summary's verdict (:func:`scara_collab.records.verdict.apply`) takes the
launcher's ``exit_code`` from :attr:`RunRecord.extra` and keeps it unless it is 0.

Other recordings of the run (the launcher's ``--record``:
:class:`scara_collab.nodes.mcap_recorder.McapRecorder`) go into :attr:`RunRecord.sinks`; they
record until the end of the run, past the window, and :meth:`RunRecord.finish` closes them
first.

>>> import tempfile
>>> folder = tempfile.TemporaryDirectory()
>>> record = RunRecord(folder.name, 'single')
>>> record.add_state(1.0, [0.0, 1.57, 0.0], [0.0, -1.57, 0.0]); record.start_job()
1.0
>>> summary = record.finish('duration reached', False, plots=False)
>>> summary['joint_state_rows'], round(summary['min_separation_m'], 3)
(1, 1.9)
>>> summary['exit_code'], summary['exit_reason'], summary['problems']
(0, 'duration reached', [])
>>> folder.cleanup()
"""
import logging
from pathlib import Path
import time
from typing import Dict, List, Optional, Sequence, Union

from scara_collab.core.config import load_config
from scara_collab.core.job import items_per_minute
from scara_collab.core.model import CellModel, load_cell
from scara_collab.core.sorting import GONE
from scara_collab.graph import BY_NAME, LAUNCH_MODES
from scara_collab.records import report, verdict
from scara_collab.records.graph_watch import GraphWatch
from scara_collab.records.person import PersonLog
from scara_collab.records.stops import StopLog
from scara_collab.records.telemetry import RunLog

MODES = LAUNCH_MODES
#: the nodes a run has one of each: the cell's and the launcher's own (two: a second graph)
ONE_PER_RUN = tuple(BY_NAME) + ('run_recorder', 'launch_cell_watch')


def mirror_fields(mirror, log: Optional[RunLog]) -> Dict[str, object]:
    """Return the summary's mirror error fields (all None outside a mirrored run).

    :param mirror: the replication manager's newest ``MirrorStatus``, or None;
    :param log: the run log (its whole-run mirror error), or None.
    """
    m = mirror
    return {
        'mirror_error_max_m': None if m is None else m.error_max,
        'mirror_error_source': None if m is None else 'replication_manager, in-step moves',
        'mirror_in_step_moves': None if m is None else m.in_step_moves,
        'mirror_not_in_step': None if m is None else m.not_in_step,
        'mirror_not_in_step_reason': None if m is None else m.last_reason,
        'mirror_error_whole_run_max_m': None if log is None else log.max_mirror_error,
        'mirror_error_whole_run_time': None if log is None else log.max_mirror_error_time}


def state_fields(log: RunLog, refused: int) -> Dict[str, object]:
    """Return the summary's fields about the joint states kept (``refused``: at the door)."""
    return {'joint_state_rows': log.rows, 'joint_states_missing': log.missing,
            'joint_states_refused': refused, 'largest_gap_s': log.largest_gap,
            'joint_speed_max_ratio': round(log.max_speed_ratio, 3),
            'overspeed_count': log.overspeed_count, 'overspeed': list(log.overspeed)}


class RunRecord:
    """Record one run into ``directory``.

    :param directory: the run folder (created if needed).
    :param mode: ``idle``, ``single``, ``collaborative`` or ``mirrored``.
    :param cell: the cell model; default ``load_cell(profile)``.
    :param profile: link profile for the default cell model (and the summary).
    :param batch: joint states per CSV write (see :class:`RunLog`).
    :param person: the run's person scenario, ``''`` for none: with one, the record keeps
        :attr:`person` (:class:`~scara_collab.records.person.PersonLog`, its CSV files) and the
        summary its ``person`` block; without, neither.
    """

    def __init__(self, directory: Union[str, Path], mode: str = 'idle',
                 cell: Optional[CellModel] = None, profile: Optional[str] = None,
                 batch: int = 200, person: str = ''):
        """Open the run log; nothing is heard yet and the window is not started."""
        if mode not in MODES:
            raise ValueError(f'mode must be one of {MODES}, got {mode!r}')
        self.mode = mode
        self.profile = profile
        self.cell = cell if cell is not None else load_cell(profile)
        period = 1.0 / float(load_config('simulation')['state_rate'])
        self.log = RunLog(directory, self.cell, batch=batch, state_period=period)
        self.directory = self.log.directory
        #: what the person did and what the separation monitor made of it (None: no person)
        self.person: Optional[PersonLog] = PersonLog(
            self.directory, person, [a.name for a in self.cell.arms], batch) if person else None
        self.stats: Dict[str, object] = {}
        self.stats_time: Optional[float] = None
        self.monitor = None   # the newest MonitorStatus (scara_collab.nodes.protocol)
        self.mirror = None    # the newest MirrorStatus
        self.estops: List[float] = []  # rising edges of /emergency_stop, sim s
        self.estop_active = False
        self.stop_log = StopLog()      # protective and emergency stops
        self.graph_watch = GraphWatch(ONE_PER_RUN)  # foreign clocks, second graphs
        self.created_wall = time.monotonic()
        self.refused = 0      # joint states refused at the door (stamps, non-finite values)
        self.extra: Dict[str, object] = {}
        self.job_start: Optional[float] = None      # sim s
        self.job_start_wall: Optional[float] = None
        self.end: Optional[float] = None            # sim s, set by freeze()
        self.end_wall: Optional[float] = None
        self.first_state_wall: Optional[float] = None
        self.summary: Optional[Dict] = None
        self.plots: List[Path] = []
        # more recordings of the run (e.g. McapRecorder): closed by finish(), first; close()
        # returns a dict merged into the summary
        self.sinks: List = []

    # --- time ------------------------------------------------------------------------------
    @property
    def sim_time(self) -> float:
        """The run's time now, sim s: the last state's stamp (the node's clock, on a node)."""
        return self.log.t_last or 0.0

    @property
    def recording(self) -> bool:
        """True until :meth:`freeze` (or the end of the run)."""
        return self.end is None and not self.log.closed

    def report_error(self, text: str) -> None:
        """Say that a part of the run's output failed (a node logs it as its own error)."""
        logging.getLogger(__name__).error(text)

    # --- input -----------------------------------------------------------------------------
    def add_state(self, t: float, q_leader: Sequence[float], q_follower: Sequence[float]) -> None:
        """Record one joint state of both arms at sim time ``t`` s (leader, follower)."""
        if self.first_state_wall is None:
            self.first_state_wall = time.monotonic()
        self.log.add_state(t, q_leader, q_follower)

    def add_stats(self, stats: Dict[str, object]) -> None:
        """Keep the job's own figures (give-ups, retries, phases, ...), heard now."""
        self.stats = stats
        self.stats_time = self.sim_time

    def add_estop(self, on: bool) -> None:
        """Take the latched ``/emergency_stop`` now (the bridge obeys it, whoever sends it).

        A rising edge is kept in :attr:`estops`; a hold no emergency stop event covers is
        listed in the summary's ``emergency_stops`` (:class:`StopLog`).
        """
        if on and not self.estop_active:
            self.estops.append(self.sim_time)
        self.estop_active = on
        self.stop_log.request(on, self.sim_time)

    def add_stop(self, kind: str, state: str, t: float, cause: str,
                 since: Optional[float] = None) -> None:
        """Take a stop event: a ``kind`` stop's ``state`` (begin, end) at sim time ``t``."""
        self.stop_log.event(kind, state, t, cause, since)

    def take_monitor(self, status) -> None:
        """Keep the collision monitor's newest status (a ``MonitorStatus``)."""
        self.monitor = status
        self.stop_log.monitor(status.time, status.stopped, getattr(status, 'kind', ''),
                              status.reason)

    def look_at_graph(self, clock_publishers: Sequence[str], nodes: Sequence[str]) -> None:
        """Take one look at the graph: ``/clock``'s publishers and every node (full names)."""
        self.graph_watch.look(self.sim_time, time.monotonic() - self.created_wall,
                              clock_publishers, nodes)

    def clock_back(self, before: float, after: float) -> None:
        """Take a backward jump of the run's clock (sim s): a foreign clock."""
        self.graph_watch.clock_back(before, after)

    # --- the run window --------------------------------------------------------------------
    def start_job(self, t: Optional[float] = None) -> float:
        """Mark the start of the job window (default: now, sim time); returns it."""
        self.job_start = self.sim_time if t is None else float(t)
        self.job_start_wall = time.monotonic()
        return self.job_start

    def freeze(self, t: Optional[float] = None) -> None:
        """End the window (default: the last recorded state); later messages are ignored."""
        if self.end is not None:
            return
        self.log.flush()
        if self.person is not None:
            self.person.flush()
        if t is not None:
            self.end = float(t)
        else:
            self.end = self.log.t_last if self.log.t_last is not None else self.sim_time
        self.end_wall = time.monotonic()

    def window(self):
        """``(t_start, t_end, wall_start, wall_end)`` of the run window so far."""
        t_start = self.job_start if self.job_start is not None else (self.log.t_first or 0.0)
        t_end = self.end if self.end is not None else (self.log.t_last or t_start)
        wall_start = self.job_start_wall if self.job_start_wall is not None else (
            self.first_state_wall)
        wall_end = self.end_wall if self.end_wall is not None else time.monotonic()
        return t_start, max(t_end, t_start), wall_start, wall_end

    # --- output ----------------------------------------------------------------------------
    def progress(self) -> Dict[str, object]:
        """Numbers for the live progress line (job sim s, counts, separation, RTF)."""
        self.log.flush()
        t_start, t_end, wall_start, wall_end = self.window()
        counts = self.log.event_counts(t_start, t_end)
        wall = (wall_end - wall_start) if wall_start is not None else 0.0
        return {'sim': t_end - t_start, 'sorted': counts['sorted'], 'missed': counts['missed'],
                'items_per_minute': items_per_minute(counts['sorted'], t_end - t_start),
                'min_separation_m': self.separation()[0],
                'rtf': (t_end - t_start) / wall if wall > 0.5 else None}

    def separation(self):
        """Return ``(minimum m, time s, source)`` of the arm separation.

        The collision monitor's, or (no monitor heard) the recorded states' own, labelled so.
        """
        if self.monitor is not None and self.monitor.minimum is not None:
            return self.monitor.minimum, self.monitor.minimum_time, 'collision_monitor'
        if self.log.rows:
            return self.log.min_distance, self.log.min_distance_time, \
                'recorded joint states (no collision monitor status heard)'
        return None, None, None

    def build_summary(self, exit_reason: str, interrupted: bool) -> Dict[str, object]:
        """Return the summary of the run so far (the fields of ``summary.json``)."""
        self.log.flush()
        t_start, t_end, wall_start, wall_end = self.window()
        counts = self.log.event_counts(t_start, t_end)
        sim_seconds = t_end - t_start
        wall = (wall_end - wall_start) if wall_start is not None else 0.0
        log = self.log
        mirrored = self.mode == 'mirrored' and log.rows > 0
        sep, sep_time, sep_source = self.separation()
        summary: Dict[str, object] = {
            'mode': self.mode,
            'profile': self.profile or self.cell.profile,
            'sim_seconds': sim_seconds,
            'wall_seconds': wall,
            'real_time_factor': sim_seconds / wall if wall > 0 else None,
            **counts,
            'in_progress': counts['spawned'] + counts['received'] - sum(counts[k]
                                                                        for k in GONE),
            'items_per_minute': items_per_minute(counts['sorted'], sim_seconds),
            'counts_source': 'pybullet_bridge /conveyor/events in the job window',
            'min_separation_m': sep,
            'min_separation_time': sep_time,
            'min_separation_source': sep_source,
            'safety_margin_m': self.cell.safety_margin,
            'margin_ok': None if sep is None else bool(sep >= self.cell.safety_margin),
            **mirror_fields(self.mirror if mirrored else None, log if mirrored else None),
            **self.stop_log.summary(t_end),
            'emergency_stop_reason': None if self.monitor is None or not self.monitor.stopped
            else self.monitor.reason,
            **self.graph_watch.summary(),
            'silences': [],           # the launcher's lockstep watch gives them (extra)
            'silence_limits': None,
            'interrupted': bool(interrupted),
            'exit_reason': exit_reason,
            'job_start_sim_time': self.job_start,
            'sim_time_end': t_end,
            **state_fields(log, self.refused),
            'events': counts,
            'job': dict(self.stats),
            'job_time': self.stats_time,
            'output': str(self.directory),
        }
        if self.person is not None:
            self.person.flush()
            summary['person'] = self.person.summary(t_end)
        summary.update(self.extra)
        return summary

    def checkpoint(self) -> None:
        """Flush the CSV files and write a provisional summary (``exit_reason: running``)."""
        if self.summary is None and not self.log.closed:
            summary = self.build_summary('running', True)
            summary['problems'] = verdict.verdict(  # so far, the run going on
                dict(summary, exit_code=0, interrupted=False)).problems
            report.write_summary(self.directory, summary)

    def finish(self, exit_reason: str, interrupted: bool, plots: bool = True) -> Dict:
        """End the recording: close the CSV files, write ``summary.json`` and the plots.

        Idempotent: a second call returns the first summary. The summary's ``exit_code``,
        ``exit_reason`` and ``problems`` are the run's verdict
        (:func:`scara_collab.records.verdict.apply`); ``end_reason`` keeps ``exit_reason``.

        :param exit_reason: why the run ended, e.g. ``'duration reached'``, ``'SIGINT'``.
        :param interrupted: False only for a run that reached its end normally.
        :param plots: draw the PNG plots too.
        :return: the summary written.
        """
        if self.summary is not None:
            return self.summary
        self.freeze()
        for sink in self.sinks:
            try:
                self.extra.update(sink.close() or {})
            except Exception as exc:  # noqa: BLE001 - the CSV files and summary come first
                self.extra.setdefault('sink_errors', []).append(f'{type(exc).__name__}: {exc}')
                self.report_error(f'recording not closed cleanly: {exc}')
        summary = self.build_summary(exit_reason, interrupted)
        verdict.apply(summary)
        self.log.close()
        if self.person is not None:
            self.person.close()
        report.write_summary(self.directory, summary)  # first, so it exists whatever happens
        if plots:
            try:
                self.plots = report.plot_run(self.directory, self.cell, summary)
                summary['plots'] = [p.name for p in self.plots]
            except Exception as exc:  # noqa: BLE001 - the numbers matter more than a figure
                summary['plot_error'] = f'{type(exc).__name__}: {exc}'
                self.report_error(f'plots not written: {summary["plot_error"]}')
            report.write_summary(self.directory, summary)
        self.summary = summary
        return summary

    def close(self) -> Dict:
        """Finish as interrupted unless :meth:`finish` ran; the files are complete either way."""
        return self.finish('recorder closed before the end of the run', True)
