"""``run_recorder``: the node inside the launcher that records a run (sim time).

Subscribes ``/joint_states`` (every message becomes a row of ``timeseries.csv``),
``/conveyor/events`` (``events.csv``), the latched ``/emergency_stop``, and the statuses that
own the run's figures (:mod:`scara_collab.nodes.protocol`), one source per figure:

================================  =====================================================
summary field                     source
================================  =====================================================
sorted, missed, dropped, ...      the bridge's ``/conveyor/events`` inside the job window
items_per_minute                  those counts over the window
                                  (:func:`scara_collab.core.job.items_per_minute`)
min_separation_m                  ``/collision_monitor/status`` (its minimum)
mirror_error_max_m                ``/replication_manager/status`` (in-step moves)
job (give-ups, retries, phases)   ``/automation_manager/stats``
================================  =====================================================
 The numbers are computed by
:mod:`scara_collab.run.telemetry`; the summary and the plots are written by
:mod:`scara_collab.run.report` when the run ends (:meth:`RunRecorder.finish`), or with
``interrupted: true`` when the recorder is closed before that (:meth:`RunRecorder.close`).

The launcher tells the recorder when the job window starts (:meth:`RunRecorder.start_job`)
and ends (:meth:`RunRecorder.freeze`); ``sim_seconds``, ``wall_seconds``, the real-time factor
and the item counts of the summary refer to that window. The handlers ``on_*`` are public so a
test can feed them messages directly.

Other recordings that live on this node (the launcher's ``--record``:
:class:`scara_collab.run.mcap_log.McapLog`) go into :attr:`RunRecorder.sinks`; they record
until the end of the run, past the window, and :meth:`RunRecorder.finish` closes them first.
"""
import math
from pathlib import Path
import time
from typing import Dict, List, Optional, Union

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from scara_collab.core.config import load_config
from scara_collab.core.job import items_per_minute
from scara_collab.core.model import CellModel, load_cell
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.qos import LATCHED
from scara_collab.nodes.runner import guarded
from scara_collab.run import report
from scara_collab.run.telemetry import RunLog

STATE_QOS = QoSProfile(depth=200)   # a burst of joint states while the launcher is busy
EVENTS_QOS = QoSProfile(depth=100)
MODES = ('idle', 'single', 'collaborative', 'mirrored')


class RunRecorder(Node):
    """Record one run into ``directory``.

    :param directory: the run folder (created if needed).
    :param mode: ``idle``, ``single``, ``collaborative`` or ``mirrored``.
    :param cell: the cell model; default ``load_cell(profile)``.
    :param profile: link profile for the default cell model (and the summary).
    :param batch: joint states per CSV write (see :class:`RunLog`).
    :param kwargs: passed to :class:`rclpy.node.Node` (e.g. ``context``).
    """

    def __init__(self, directory: Union[str, Path], mode: str = 'idle',
                 cell: Optional[CellModel] = None, profile: Optional[str] = None,
                 batch: int = 200, **kwargs):
        """Create the node on sim time, open the run log and subscribe the topics it records."""
        overrides = list(kwargs.pop('parameter_overrides', []))
        overrides.append(Parameter('use_sim_time', Parameter.Type.BOOL, True))
        super().__init__('run_recorder', parameter_overrides=overrides, **kwargs)
        if mode not in MODES:
            raise ValueError(f'mode must be one of {MODES}, got {mode!r}')
        self.mode = mode
        self.profile = profile
        self.cell = cell if cell is not None else load_cell(profile)
        period = 1.0 / float(load_config('simulation')['state_rate'])
        self.log = RunLog(directory, self.cell, batch=batch, state_period=period)
        self.directory = self.log.directory
        self.stats: Dict[str, object] = {}
        self.stats_time: Optional[float] = None
        self.monitor: Optional[proto.MonitorStatus] = None
        self.mirror: Optional[proto.MirrorStatus] = None
        self.estops: List[float] = []
        self.estop_active = False
        self.extra: Dict[str, object] = {}
        self.job_start: Optional[float] = None      # sim s
        self.job_start_wall: Optional[float] = None
        self.end: Optional[float] = None            # sim s, set by freeze()
        self.end_wall: Optional[float] = None
        self.first_state_wall: Optional[float] = None
        self.summary: Optional[Dict] = None
        self.stamps = conv.StampGate()  # states must carry the sim clock's time
        self.plots: List[Path] = []
        # more recordings on this node (e.g. mcap_log.McapLog): closed by finish(), first;
        # close() returns a dict merged into the summary
        self.sinks: List = []
        self._index: Dict[tuple, np.ndarray] = {}
        self._names = list(self.cell.leader.joint_names) + list(self.cell.follower.joint_names)
        # no exception escapes a callback (runner.guarded: logged, the recording goes on)
        for msg_type, topic, callback, qos in (
                (JointState, '/joint_states', self.on_joint_state, STATE_QOS),
                (DiagnosticStatus, '/conveyor/events', self.on_event, EVENTS_QOS),
                (DiagnosticStatus, '/automation_manager/stats', self.on_stats, 10),
                (DiagnosticStatus, '/collision_monitor/status', self.on_monitor, 10),
                (DiagnosticStatus, '/replication_manager/status', self.on_mirror, 10),
                (Bool, '/emergency_stop', self.on_estop, LATCHED)):
            self.create_subscription(msg_type, topic, guarded(self, callback), qos)

    # --- time ------------------------------------------------------------------------------
    @property
    def sim_time(self) -> float:
        """Latest sim time heard on ``/clock``, s; 0 before any.

        The run's time is the bridge's clock, never a joint state's stamp: states are let
        through only when their stamps agree with it (:class:`conversions.StampGate`).
        """
        return self.get_clock().now().nanoseconds * 1e-9

    @property
    def recording(self) -> bool:
        """True until :meth:`freeze` (or the end of the run)."""
        return self.end is None and not self.log.closed

    # --- handlers --------------------------------------------------------------------------
    def on_joint_state(self, msg: JointState) -> None:
        """Queue a row for ``timeseries.csv``: the six joints of both arms at the stamp."""
        if not self.recording or not conv.admit_state(self, self.stamps, msg):
            return
        key = tuple(msg.name)
        idx = self._index.get(key)
        if idx is None:
            where = {n: i for i, n in enumerate(key)}
            missing = [n for n in self._names if n not in where]
            if missing:
                self.get_logger().warning(f'joint_states lacks {missing}; not recorded',
                                          throttle_duration_sec=10.0)
                return
            idx = self._index[key] = np.array([where[n] for n in self._names])
        if len(msg.position) != len(key):
            return
        q = np.asarray(msg.position, dtype=float)[idx]
        if not np.all(np.isfinite(q)):
            self.stamps.refused += 1
            self.get_logger().warning('joint_states with non-finite positions; not recorded',
                                      throttle_duration_sec=10.0)
            return
        if self.first_state_wall is None:
            self.first_state_wall = time.monotonic()
        self.log.add_state(conv.to_sec(msg.header.stamp), q[:3], q[3:])

    def on_event(self, msg: DiagnosticStatus) -> None:
        """Record a conveyor event (:class:`~scara_collab.nodes.protocol.ItemEvent`)."""
        if not self.recording:
            return
        try:
            ev = proto.ItemEvent.from_msg(msg)
        except proto.ProtocolError as exc:
            self.get_logger().warning(f'ignoring an item event: {exc}', throttle_duration_sec=5.0)
            return
        t = ev.time if math.isfinite(ev.time) else self.sim_time
        self.log.add_event(t, ev.kind, ev.item, ev.cls, ev.robot, ev.cause)

    def on_stats(self, msg: DiagnosticStatus) -> None:
        """Keep the job's own figures (:class:`~scara_collab.nodes.protocol.JobStats`)."""
        if not self.recording:
            return
        try:
            st = proto.JobStats.from_msg(msg)
        except proto.ProtocolError as exc:
            self.get_logger().warning(f'ignoring job stats: {exc}', throttle_duration_sec=5.0)
            return
        self.stats = {'give_ups': st.give_ups, 'retries': st.retries,
                      'last_give_up': st.last_give_up, 'phases': st.phases,
                      'running': st.running, 'time': st.time}
        self.stats_time = self.sim_time

    def on_monitor(self, msg: DiagnosticStatus) -> None:
        """Keep the collision monitor's figures (the minimum separation's source)."""
        try:
            self.monitor = proto.MonitorStatus.from_msg(msg)
        except proto.ProtocolError as exc:
            self.get_logger().warning(f'ignoring monitor status: {exc}',
                                      throttle_duration_sec=5.0)

    def on_mirror(self, msg: DiagnosticStatus) -> None:
        """Keep the replication manager's figures (the mirror error's source)."""
        try:
            self.mirror = proto.MirrorStatus.from_msg(msg)
        except proto.ProtocolError as exc:
            self.get_logger().warning(f'ignoring mirror status: {exc}',
                                      throttle_duration_sec=5.0)

    def on_estop(self, msg: Bool) -> None:
        """Count emergency stops (rising edges of ``/emergency_stop``)."""
        on = bool(msg.data)
        if on and not self.estop_active:
            self.estops.append(self.sim_time)
        self.estop_active = on

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
        mirror = self.mirror if mirrored else None
        summary: Dict[str, object] = {
            'mode': self.mode,
            'profile': self.profile or self.cell.profile,
            'sim_seconds': sim_seconds,
            'wall_seconds': wall,
            'real_time_factor': sim_seconds / wall if wall > 0 else None,
            **counts,
            'in_progress': counts['spawned'] - sum(counts[k] for k in proto.COUNTED
                                                   if k != 'spawned'),
            'items_per_minute': items_per_minute(counts['sorted'], sim_seconds),
            'counts_source': 'pybullet_bridge /conveyor/events in the job window',
            'min_separation_m': sep,
            'min_separation_time': sep_time,
            'min_separation_source': sep_source,
            'safety_margin_m': self.cell.safety_margin,
            'margin_ok': None if sep is None else bool(sep >= self.cell.safety_margin),
            'mirror_error_max_m': None if mirror is None else mirror.error_max,
            'mirror_error_source': None if mirror is None else
            'replication_manager, in-step moves',
            'mirror_in_step_moves': None if mirror is None else mirror.in_step_moves,
            'mirror_not_in_step': None if mirror is None else mirror.not_in_step,
            'mirror_not_in_step_reason': None if mirror is None else mirror.last_reason,
            'mirror_error_whole_run_max_m': log.max_mirror_error if mirrored else None,
            'mirror_error_whole_run_time': log.max_mirror_error_time if mirrored else None,
            'emergency_stops': len(self.estops),
            'emergency_stop_times': list(self.estops),
            'emergency_stop_reason': None if self.monitor is None or not self.monitor.stopped
            else self.monitor.reason,
            'interrupted': bool(interrupted),
            'exit_reason': exit_reason,
            'job_start_sim_time': self.job_start,
            'sim_time_end': t_end,
            'joint_state_rows': log.rows,
            'joint_states_missing': log.missing,
            'joint_states_refused': self.stamps.refused,
            'largest_gap_s': log.largest_gap,
            'events': counts,
            'job': dict(self.stats),
            'job_time': self.stats_time,
            'output': str(self.directory),
        }
        summary.update(self.extra)
        return summary

    def checkpoint(self) -> None:
        """Flush the CSV files and write a provisional summary (``exit_reason: running``)."""
        if self.summary is None and not self.log.closed:
            report.write_summary(self.directory, self.build_summary('running', True))

    def finish(self, exit_reason: str, interrupted: bool, plots: bool = True) -> Dict:
        """End the recording: close the CSV files, write ``summary.json`` and the plots.

        Idempotent: a second call returns the first summary.

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
                self.get_logger().error(f'recording not closed cleanly: {exc}')
        summary = self.build_summary(exit_reason, interrupted)
        self.log.close()
        report.write_summary(self.directory, summary)  # first, so it exists whatever happens
        if plots:
            try:
                self.plots = report.plot_run(self.directory, self.cell, summary)
                summary['plots'] = [p.name for p in self.plots]
            except Exception as exc:  # noqa: BLE001 - the numbers matter more than a figure
                summary['plot_error'] = f'{type(exc).__name__}: {exc}'
                self.get_logger().error(f'plots not written: {summary["plot_error"]}')
            report.write_summary(self.directory, summary)
        self.summary = summary
        return summary

    def close(self) -> Dict:
        """Finish as interrupted unless :meth:`finish` ran; the files are complete either way."""
        return self.finish('recorder closed before the end of the run', True)

    def destroy_node(self) -> bool:
        """Close the recording with the node."""
        self.close()
        return super().destroy_node()
