"""Whether every launched node still answers the lockstep: a hung process does not exit.

The lockstep answers on ``/sim/lockstep`` (hundreds a second) go to a node
(:class:`~scara_collab.nodes.lockstep_watch.LockstepWatchNode`) and an executor of their own,
which :meth:`Liveness.silent` drains when the launcher looks (once a second): a look never
waits, and a slow launcher is never a burden on the nodes (best effort, the newest 200).

With every node in one process (``--one-process``) there is nothing to watch: a node that
hangs stops that process's one thread, the bridge with it, so no node is ever behind the
others (sim time stands still instead: the launcher's stall check). The watch is then off and
subscribes nothing, which saves the container a delivery to another process for each of its
hundreds of answers a second (about 6 % of its CPU).

Each look also keeps the run's silences, whatever their length
(:meth:`~scara_collab.nodes.lockstep_watch.LockstepWatch.look`); :meth:`Liveness.summary`
hands them to the run's summary, where a silence the bridge did not wait for fails the run
(:mod:`scara_collab.records.verdict`).
"""
from typing import Dict, Iterable, Optional, Tuple

from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

from scara_collab import graph
from scara_collab.nodes import lockstep
from scara_collab.nodes.lockstep_watch import LockstepWatch, LockstepWatchNode, WATCH_QOS


class Liveness:
    """Watch the lockstep answers of the launched nodes.

    :param names: the launched nodes that answer the lockstep (``collision_monitor``); none:
        the watch is off.
    :param limit: wall seconds a node may leave a ``/clock`` unanswered (``--silent-timeout``).
    :param context: the launcher's rclpy context.
    :param namespace: the cell's namespace (default: the root): its lockstep, its nodes.
    """

    def __init__(self, names: Iterable[str], limit: float, context: Context,
                 namespace: str = ''):
        """Create the watch node and its executor."""
        self.namespace = graph.namespace_of(namespace)
        self.watch = LockstepWatch([lockstep.full_name(n, self.namespace) for n in names],
                                   limit)
        self.silent_node: Optional[str] = None  # the node found silent, once one is
        self._node = self._executor = None
        if self.watch.names:
            self._node = LockstepWatchNode(self.watch, context=context,
                                           cli_args=graph.node_args(self.namespace))
            self._executor = SingleThreadedExecutor(context=context)
            self._executor.add_node(self._node)

    def take_answers(self) -> None:
        """Take the answers kept since the last look (at most the queue, never waiting)."""
        if self._node is None:
            return
        idle = 0  # spin_once(0) takes a message only every other call or so: not the end yet
        for _ in range(4 * WATCH_QOS.depth):
            before = self._node.answers
            self._executor.spin_once(timeout_sec=0.0)
            idle = idle + 1 if self._node.answers == before else 0
            if idle >= 3:
                break

    def expect(self, wall: float) -> None:
        """Sim time starts now (``wall``): a node never heard is silent from here on."""
        self.watch.expect(wall)

    def silent(self, sim_now: float, wall: float) -> Optional[Tuple[str, float, float]]:
        """Take the answers; return ``(node, silent wall s, sim time it reached)`` or None.

        :param sim_now: the newest sim time the launcher has heard on the clock, s.
        :param wall: now, s (``time.monotonic()``).
        """
        self.take_answers()
        self.watch.look(sim_now, wall)
        silent = self.watch.silent(sim_now, wall)
        if silent is None:
            return None
        name, seconds, t = silent
        self.silent_node = name[len(self.namespace):].lstrip('/')  # its name in the cell
        return self.silent_node, seconds, t

    def summary(self) -> Dict[str, object]:
        """Return the silences for the run's summary: ``silences``, ``silence_limits``.

        ``silences``: every one seen, oldest first (node, sim time it reached, wall s, sim s
        behind, ended, dropped); ``silence_limits``: ``notice_s`` and the bridge's
        ``lockstep_timeout_s``, or None when the watch is off (``--one-process``).
        """
        if self._node is None:
            return {'silences': [], 'silence_limits': None}
        return {'silences': [s.values() for s in self.watch.silences],
                'silence_limits': {'notice_s': self.watch.notice,
                                   'lockstep_timeout_s': self.watch.drop_after}}

    def close(self) -> None:
        """Shut down the executor and destroy the watch node."""
        if self._node is not None:
            self._executor.shutdown(timeout_sec=1.0)
            self._node.destroy_node()
