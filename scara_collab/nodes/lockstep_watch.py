"""``launch_cell_watch``: the launcher's look at the lockstep answers (who stopped answering).

A process that hangs (stopped, deadlocked, starved) does not exit, so the launcher also
watches the answers on ``/sim/lockstep`` (:mod:`scara_collab.nodes.lockstep`):
:class:`LockstepWatchNode` hears them, :class:`LockstepWatch` keeps who answered what and
names the participant that left a ``/clock`` unanswered too long.
"""
import time
from typing import Dict, Iterable, Optional, Tuple

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header

from scara_collab.nodes import conversions as conv
from scara_collab.nodes import lockstep
from scara_collab.nodes.runner import guarded

# the launcher's look at /sim/lockstep, taken once a second: the newest 200 answers (40 clocks
# of 5 nodes; a live node is never more than the lockstep window behind), best effort so that
# a slow launcher is never a burden on the nodes
WATCH_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.BEST_EFFORT)


class LockstepWatch:
    """Who answers on ``/sim/lockstep``, and who stopped (:mod:`scara_collab.nodes.lockstep`).

    A participant is *silent* when its newest answer is older than ``limit`` wall seconds and
    behind the newest sim time (there is a ``/clock`` it has not answered): it hangs, is
    stopped or starves. Sim time that stands still with every participant up to date leaves
    nobody silent; that is the bridge's stall.

    :param names: full names of the nodes to watch (``/collision_monitor``); others ignored.
    :param limit: wall seconds.
    """

    def __init__(self, names: Iterable[str], limit: float):
        """Watch the nodes ``names``; a participant is silent after ``limit`` wall seconds."""
        self.names = frozenset(names)
        self.limit = float(limit)
        self.reached: Dict[str, float] = {}  # participant -> newest sim time it answered
        self.heard: Dict[str, float] = {}    # participant -> wall time of that answer

    def answer(self, name: str, sim_t: float, wall: float) -> None:
        """Take one answer of ``name``, at sim time ``sim_t`` (the end of time: it left)."""
        if name not in self.names:
            return
        if sim_t >= lockstep.END_OF_TIME.sec:
            self.reached.pop(name, None)
            self.heard.pop(name, None)
        elif sim_t > self.reached.get(name, -1.0):
            self.reached[name], self.heard[name] = sim_t, wall

    def expect(self, wall: float) -> None:
        """Count every watched node not heard yet as having answered sim time 0 at ``wall``.

        Called when sim time starts (the launcher resumes the paused bridge): a node that
        never answers at all (stopped before its first answer) is silent like any other.
        """
        for name in self.names - set(self.reached):
            self.reached[name], self.heard[name] = 0.0, wall

    def silent(self, sim_now: float, wall: float) -> Optional[Tuple[str, float, float]]:
        """Return ``(name, silent wall s, sim time it reached)`` of the longest silent one.

        :param sim_now: the newest sim time the launcher has heard on ``/clock``, s.
        :param wall: now, s (the clock of :meth:`answer`'s ``wall``).
        :return: ``None`` if nobody is silent beyond the limit.
        """
        front = max([sim_now, *self.reached.values()])
        late = [(wall - self.heard[n], n) for n, t in self.reached.items()
                if t < front - 1e-6 and wall - self.heard[n] > self.limit]
        if not late:
            return None
        silent, name = max(late)
        return name, silent, self.reached[name]


class LockstepWatchNode(Node):
    """Hear the lockstep answers for ``watch`` (wall time of arrival); count them.

    :param watch: where the answers go.
    :param kwargs: passed to :class:`rclpy.node.Node` (e.g. ``context``).
    """

    def __init__(self, watch: LockstepWatch, **kwargs):
        """Create the node and subscribe ``/sim/lockstep`` (best effort, :data:`WATCH_QOS`)."""
        super().__init__('launch_cell_watch', **kwargs)
        self.watch = watch
        self.answers = 0
        self.create_subscription(Header, lockstep.TOPIC, guarded(self, self.on_answer),
                                 WATCH_QOS)

    def on_answer(self, msg: Header) -> None:
        """Take one answer: its signer (``frame_id``) reached sim time ``stamp``."""
        self.answers += 1
        self.watch.answer(msg.frame_id, conv.to_sec(msg.stamp), time.monotonic())
