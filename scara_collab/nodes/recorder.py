"""``run_recorder``: the node inside the launcher that records a run (sim time).

Subscribes ``joint_states`` (every message becomes a row of ``timeseries.csv``),
``/conveyor/events`` (``events.csv``), the latched ``/emergency_stop``, the collision
monitor's stops (``/collision_monitor/stops``) and the statuses that own the run's figures
(:mod:`scara_collab.nodes.protocol`); names, types and QoS are the graph's
(:func:`scara_collab.graph.topic`, :func:`scara_collab.nodes.qos.recording`). While it
records it also looks at the graph once a wall second (the clock's publishers, the node
names: :meth:`RunRecorder.look`) and notes each backward jump of its sim clock, for the
summary's foreign clocks and second graphs. Its names are relative: in a cell's ``namespace``
it records that cell (:func:`scara_collab.graph.node_args`) and looks at that cell's clock and
node names only. With a person scenario (``person``) it also subscribes ``/person/truth``,
``/separation_monitor/status`` and each arm's ``trajectory_clock`` for the summary's
``person`` block (:mod:`scara_collab.records.person`); without one it does not. The node is
the subscriptions, the looks and the message conversions; what it hears is kept by the
record it also is (:class:`scara_collab.records.record.RunRecord`: the files, the job window,
the summary, the plots, the verdict). The handlers ``on_*`` are public so a test can feed
them messages directly.
"""
import math
from pathlib import Path
from typing import Dict, Optional, Union

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
from rclpy.clock import Clock, ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from scara_collab import graph
from scara_collab.core.model import CellModel
from scara_collab.nodes import conversions as conv
from scara_collab.nodes import protocol as proto
from scara_collab.nodes import qos
from scara_collab.nodes.guarded import guarded
from scara_collab.records.graph_watch import full_name, GraphWatch
from scara_collab.records.record import ONE_PER_RUN, RunRecord

#: wall s between two looks at the graph
LOOK_PERIOD = 1.0


class RunRecorder(Node, RunRecord):
    """Record one run into ``directory``: the ``run_recorder`` node and its record.

    :param directory: the run folder (created if needed).
    :param mode: ``idle``, ``single``, ``collaborative`` or ``mirrored``.
    :param cell: the cell model; default ``load_cell(profile)``.
    :param profile: link profile for the default cell model (and the summary).
    :param batch: joint states per CSV write (see :class:`RunLog`).
    :param namespace: the cell's namespace (default: the root).
    :param person: the run's person scenario (its name, or its file), ``''`` for none (the
        launcher's ``--person``): with one the node records the person's topics and the
        summary has its ``person`` block.
    :param kwargs: passed to :class:`rclpy.node.Node` (e.g. ``context``).
    """

    def __init__(self, directory: Union[str, Path], mode: str = 'idle',
                 cell: Optional[CellModel] = None, profile: Optional[str] = None,
                 batch: int = 200, namespace: str = '', person: str = '', **kwargs):
        """Create the node on sim time, open the record and subscribe the topics it records."""
        overrides = list(kwargs.pop('parameter_overrides', []))
        overrides.append(Parameter('use_sim_time', Parameter.Type.BOOL, True))
        self.namespace = graph.namespace_of(namespace)
        cli_args = graph.node_args(self.namespace) + list(kwargs.pop('cli_args', None) or [])
        Node.__init__(self, 'run_recorder', parameter_overrides=overrides, cli_args=cli_args,
                      **kwargs)
        RunRecord.__init__(self, directory, mode, cell, profile, batch, person)
        self.graph_watch = GraphWatch(ONE_PER_RUN, self.namespace)  # this cell's names
        self.clock_topic = graph.resolve(graph.CLOCK, self.namespace)
        self.stamps = conv.StampGate()  # states must carry the sim clock's time
        self._index: Dict[tuple, np.ndarray] = {}
        self._names = list(self.cell.leader.joint_names) + list(self.cell.follower.joint_names)
        # no exception escapes a callback (nodes.guarded: logged, the recording goes on)
        for name, callback in (('joint_states', self.on_joint_state),
                               ('conveyor/events', self.on_event),
                               ('automation_manager/stats', self.on_stats),
                               ('collision_monitor/status', self.on_monitor),
                               ('replication_manager/status', self.on_mirror),
                               ('collision_monitor/stops', self.on_stop),
                               ('emergency_stop', self.on_estop)):
            self._subscribe(name, callback)
        if self.person is not None:
            self._subscribe('person/truth', self.on_truth)
            self._subscribe('separation_monitor/status', self.on_separation)
            for arm in self.cell.arms:
                self._subscribe(f'{arm.name}/trajectory_clock', self.on_clock)
        # who else is on the domain: looks on wall time (sim time may stand still or be
        # foreign), and the clock's backward jumps (the time source takes each /clock anyway)
        self.create_timer(LOOK_PERIOD, guarded(self, self.look),
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._jump = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=False), post_callback=guarded(self, self.on_jump))

    def _subscribe(self, name: str, callback) -> None:
        """Subscribe the graph's topic ``name`` (relative) with its recording QoS."""
        topic = graph.topic(name, [a.name for a in self.cell.arms])
        self.create_subscription(graph.message_class(topic.type), name,
                                 guarded(self, callback), qos.recording(topic))

    @property
    def sim_time(self) -> float:
        """Latest sim time heard on the cell's clock, s; 0 before any.

        The run's time is the bridge's clock, never a joint state's stamp: states are let
        through only when their stamps agree with it (:class:`conversions.StampGate`).
        """
        return self.get_clock().now().nanoseconds * 1e-9

    def report_error(self, text: str) -> None:
        """Log that a part of the run's output failed, as this node's error."""
        self.get_logger().error(text)

    # --- handlers --------------------------------------------------------------------------
    def on_joint_state(self, msg: JointState) -> None:
        """Queue a row for ``timeseries.csv``: the six joints of both arms at the stamp."""
        if not self.recording:
            return
        if not conv.admit_state(self, self.stamps, msg):
            self.refused += 1
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
            self.refused += 1
            self.get_logger().warning('joint_states with non-finite positions; not recorded',
                                      throttle_duration_sec=10.0)
            return
        self.add_state(conv.to_sec(msg.header.stamp), q[:3], q[3:])

    def _read(self, kind, msg: DiagnosticStatus, what: str):
        """Return ``kind.from_msg(msg)``, or None (a throttled warning) if it breaks protocol."""
        try:
            return kind.from_msg(msg)
        except proto.ProtocolError as exc:
            self.get_logger().warning(f'ignoring {what}: {exc}', throttle_duration_sec=5.0)
            return None

    def on_event(self, msg: DiagnosticStatus) -> None:
        """Record a conveyor event (:class:`~scara_collab.nodes.protocol.ItemEvent`).

        Once the window is closed (:meth:`freeze`), an event stamped within it still counts:
        on a starved machine the state of the end comes in before the last events, on
        another topic, and the run would undercount what it did.
        """
        ev = self._read(proto.ItemEvent, msg, 'an item event') if not self.log.closed else None
        if ev is None:
            return
        t = ev.time if math.isfinite(ev.time) else self.sim_time
        if self.recording or (self.end is not None and t <= self.end + 1e-9):
            self.log.add_event(t, ev.kind, ev.item, ev.cls, ev.robot, ev.cause)

    def on_stats(self, msg: DiagnosticStatus) -> None:
        """Keep the job's own figures (:class:`~scara_collab.nodes.protocol.JobStats`)."""
        st = self._read(proto.JobStats, msg, 'job stats') if self.recording else None
        if st is not None:
            self.add_stats({'give_ups': st.give_ups, 'retries': st.retries,
                            'last_give_up': st.last_give_up, 'phases': st.phases,
                            'running': st.running, 'time': st.time})
            if self.person is not None:
                self.person.add_stats(st.missed_due_to_person)

    def _in_window(self, t: float) -> bool:
        """Return True for a sim time ``t`` in the run's window: recording, or before its end."""
        return self.recording or (self.end is not None and not self.log.closed
                                  and t <= self.end + 1e-9)

    def on_truth(self, msg: DiagnosticStatus) -> None:
        """Take where the person really is (a ``PersonTruth``)."""
        tr = self._read(proto.PersonTruth, msg, 'the person truth')
        if tr is not None and math.isfinite(tr.time) and self._in_window(tr.time):
            self.person.add_truth(tr.time, tr.present, tr.separation, tr.margin, tr.moving,
                                  tr.contact)

    def on_separation(self, msg: DiagnosticStatus) -> None:
        """Take the separation monitor's decision (a ``SeparationStatus``)."""
        st = self._read(proto.SeparationStatus, msg, 'a separation status')
        if st is not None and math.isfinite(st.time) and self._in_window(st.time):
            self.person.add_status(st.time, st.scale, st.stop, st.separation, st.margin,
                                   st.fault)

    def on_clock(self, msg: DiagnosticStatus) -> None:
        """Take an arm's trajectory clock (a ``TrajectoryClock``)."""
        clock = self._read(proto.TrajectoryClock, msg, 'a trajectory clock')
        if clock is not None and math.isfinite(clock.time) and self._in_window(clock.time):
            self.person.add_clock(clock.robot, clock.lag, clock.held_back)

    def on_monitor(self, msg: DiagnosticStatus) -> None:
        """Keep the collision monitor's figures (the minimum separation's source, its stop)."""
        status = self._read(proto.MonitorStatus, msg, 'monitor status')
        if status is not None:
            self.take_monitor(status)

    def on_stop(self, msg: DiagnosticStatus) -> None:
        """Take a stop's begin or end (:class:`~scara_collab.nodes.protocol.StopEvent`)."""
        ev = self._read(proto.StopEvent, msg, 'a stop event')
        if ev is None:
            return
        if ev.state not in ('begin', 'end') or not math.isfinite(ev.time):
            self.get_logger().warning(f'ignoring a stop event: state {ev.state!r}, time '
                                      f'{ev.time}', throttle_duration_sec=5.0)
            return
        since = ev.since if ev.since is not None and math.isfinite(ev.since) else None
        self.add_stop(ev.kind, ev.state, ev.time, ev.cause, since)

    def on_mirror(self, msg: DiagnosticStatus) -> None:
        """Keep the replication manager's figures (the mirror error's source)."""
        status = self._read(proto.MirrorStatus, msg, 'mirror status')
        if status is not None:
            self.mirror = status

    def on_estop(self, msg: Bool) -> None:
        """Take the latched ``emergency_stop`` (its holds, its rising edges)."""
        self.add_estop(bool(msg.data))

    def on_jump(self, jump) -> None:
        """Note a backward jump of the sim clock (a clock older than the last one)."""
        after = self.sim_time
        self.clock_back(after - jump.delta.nanoseconds * 1e-9, after)

    def look(self) -> None:
        """Look at the graph (wall timer, while recording): the clock's publishers, the nodes."""
        if not self.recording:
            return
        clocks = [full_name(i.node_namespace, i.node_name)
                  for i in self.get_publishers_info_by_topic(self.clock_topic)]
        nodes = [full_name(ns, n) for n, ns in self.get_node_names_and_namespaces()]
        self.look_at_graph(clocks, nodes)

    def destroy_node(self) -> bool:
        """Close the recording with the node."""
        self.close()
        return super().destroy_node()
