"""Record a run's topics raw into an MCAP file (the launcher's ``--record``).

:class:`McapRecorder` subscribes the topics raw (``raw=True``: the CDR bytes as they came off the
wire) on a node of its own that no executor spins; a wall-clock timer on the node it is given
(the launcher's run recorder) drains their queues every ``period`` and hands every message,
with its receive time, to the file (:class:`scara_collab.records.mcap_log.McapWriter`, which says
how the file is laid out and timed). The topics and their QoS are the graph's
(:func:`scara_collab.graph.topics`, :func:`scara_collab.nodes.qos.recording`). A node in a
cell's namespace records that cell's topics (``/cell_1/joint_states``); the file names them as
a cell in the root namespace would (``/joint_states``), so every cell's file reads alike.

Usage (a sketch, not a doctest: it needs a running node, e.g. the launcher's run
recorder)::

    log = McapRecorder(node, 'runs/x/run.mcap', robots=('scara_left', 'scara_right'))
    ...                                   # spin the node: its timer drains the topics
    log.close()                           # {'mcap': {'file': ..., 'messages': ...}}
"""
from pathlib import Path
from typing import Dict, Iterable, List, Optional, Sequence, Union

from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from scara_collab import graph
from scara_collab.nodes import qos
from scara_collab.records.mcap_log import McapWriter


class McapRecorder(McapWriter):
    """Write the topics of a run into an MCAP file, taken raw from the graph.

    :param node: the node whose executor drives the recording (a wall-clock timer on it drains
        the subscriptions every ``period``) and whose ``use_sim_time`` selects sim log times.
    :param path: the ``.mcap`` file (its folder is created; an existing file is replaced).
    :param topics: what to record; default :func:`scara_collab.graph.topics` of ``robots``.
    :param robots: robot namespaces for the default topics.
    :param period: wall seconds between drains (each subscription queues ``depth`` messages:
        200 = 2 sim s of a 100 Hz topic, enough up to 40x real time).
    :param writer: more keywords of :class:`McapWriter` (``chunk_size``, ``compression``,
        ``flush_period``).
    :raises FileNotFoundError: if a message definition is missing (nothing is subscribed).
    """

    def __init__(self, node: Node, path: Union[str, Path],
                 topics: Optional[Iterable[graph.Topic]] = None,
                 robots: Sequence[str] = graph.ROBOTS, period: float = 0.05, **writer):
        """Open the file, subscribe every topic raw and start the timer that drains them."""
        wire: Dict[str, str] = {}  # name in the file -> name on the graph (else the same)
        if topics is None:
            topics = graph.topics(robots)
            ns = graph.namespace_of(node.get_namespace())
            wire = {t.name: w.name for t, w in zip(topics, graph.topics(robots, ns))}
        topics = list(topics)
        classes = {t.type: graph.message_class(t.type) for t in topics}
        super().__init__(path, topics, sim_clock=node.get_parameter('use_sim_time').value,
                         **writer)
        self.node = node
        self._clock = node.get_clock()
        # The subscriptions live on a node of their own that no executor spins: drain() takes
        # their queues in one go (rclpy's take_message), which costs a fifth of an executor
        # callback per message and leaves the recorder node's wait set as it was.
        self._reader = Node(f'{node.get_name()}_mcap_log', namespace=node.get_namespace(),
                            context=node.context, start_parameter_services=False)
        self._subs: List = [
            self._reader.create_subscription(classes[t.type], wire.get(t.name, t.name),
                                             _never_called, qos.recording(t), raw=True)
            for t in self.wire_topics]
        self._timer = node.create_timer(float(period), self.drain,
                                        clock=Clock(clock_type=ClockType.STEADY_TIME))

    def drain(self) -> int:
        """Write every message waiting in the subscriptions, in receive order; return how many.

        Log times: see :mod:`scara_collab.records.mcap_log` (receive order from the middleware's
        receive timestamps; sim time from the ``/clock`` messages among them).
        """
        if self.closed:
            return 0
        batch = []
        for k, sub in enumerate(self._subs):
            with sub.handle:
                while True:
                    taken = sub.handle.take_message(sub.msg_type, True)
                    if taken is None:
                        break
                    batch.append((taken[1].get('received_timestamp') or 0, k, taken[0]))
        if not batch:
            return 0
        return self.write(batch, 0 if self.sim_clock else self._clock.now().nanoseconds)

    def close(self) -> Dict[str, object]:
        """Drain what is still queued, then write the summary and the footer (idempotent).

        :return: ``{'mcap': {'file', 'messages', 'topics', 'bytes'}}`` for the run summary.
        """
        if self.closed:
            return super().close()
        try:
            self.drain()
        finally:
            try:
                self.node.destroy_timer(self._timer)
                self._reader.destroy_node()
            except Exception:  # noqa: BLE001 - the context may be gone; write the file
                pass
            summary = super().close()
        return summary


def _never_called(_msg) -> None:
    """Do nothing: the drained subscriptions' node is spun by no executor."""
