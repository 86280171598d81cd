"""``launch_cell_watch``: the launcher's look at the lockstep answers (who stopped answering).

A process that hangs (stopped, deadlocked, starved) does not exit, so the launcher also
watches the answers on ``/sim/lockstep`` (:mod:`scara_collab.nodes.lockstep`):
:class:`LockstepWatchNode` hears them, :class:`LockstepWatch` keeps who answered what, names
the participant that left a ``/clock`` unanswered too long, and keeps every *silence* of the
run (:class:`Silence`): a participant behind the newest sim time that has not answered for
:data:`NOTICE` wall seconds, or that sim time left :data:`NOTICE` sim seconds behind.

The launcher looks once a wall second, and an answer counts as heard when a look takes it,
so a silence's wall length is known to about a second: at least ``wall_s`` when it is seen,
at most about a second more when it ends. :data:`NOTICE` is therefore 1.5 s: a node is named
once it has let a whole look go by without an answer while the others answered, which a
healthy node does not do even on a loaded machine (sim time waits for it instead, within the
lockstep window). A silence longer than the bridge's ``lockstep_timeout``
(:data:`LOCKSTEP_TIMEOUT`, wall s) or that sim time left that far behind (the bridge's
measure in real time, ``lockstep_window`` 0) is one the bridge did not wait for:
``dropped``, and the run fails (:mod:`scara_collab.records.verdict`).
"""
from dataclasses import asdict, dataclass
import time
from typing import Dict, Iterable, List, Optional, Tuple

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header

from scara_collab.nodes import conversions as conv
from scara_collab.nodes import lockstep
from scara_collab.nodes.guarded import guarded

# the launcher's look at /sim/lockstep, taken once a second: the newest 200 answers (40 clocks
# of 5 nodes; a live node is never more than the lockstep window behind), best effort so that
# a slow launcher is never a burden on the nodes
WATCH_QOS = QoSProfile(depth=200, reliability=ReliabilityPolicy.BEST_EFFORT)
#: wall s without an answer (or sim s left behind) that make a participant silent
NOTICE = 1.5
#: the bridge's default ``lockstep_timeout`` (wall s; sim s behind with lockstep off): how
#: long it waits for a participant before sim time goes on without it
LOCKSTEP_TIMEOUT = 5.0


@dataclass
class Silence:
    """One silence of a participant: who, from which sim time, how long (wall s, sim s behind).

    ``ended``: it answered again (or left the lockstep) before the run's last look;
    ``dropped``: longer than the bridge's ``lockstep_timeout``.
    """

    node: str
    sim_time: float
    wall_s: float = 0.0
    lag_s: float = 0.0
    ended: bool = False
    dropped: bool = False

    def values(self) -> Dict[str, object]:
        """Return the silence as the summary lists it (node name without its ``/``)."""
        out = asdict(self)
        out.update(node=self.node.lstrip('/'), wall_s=round(self.wall_s, 3),
                   lag_s=round(self.lag_s, 3))
        return out


class LockstepWatch:
    """Who answers on ``/sim/lockstep``, and who stopped (:mod:`scara_collab.nodes.lockstep`).

    A participant is *silent* when its newest answer is older than ``limit`` wall seconds and
    behind the newest sim time (there is a ``/clock`` it has not answered): it hangs, is
    stopped or starves. Sim time that stands still with every participant up to date leaves
    nobody silent; that is the bridge's stall.

    Every silence longer than ``notice`` is kept in :attr:`silences` (:meth:`look`).

    :param names: full names of the nodes to watch (``/collision_monitor``); others ignored.
    :param limit: wall seconds (:meth:`silent`).
    :param notice: wall seconds without an answer, or sim seconds behind, that make a
        silence (:meth:`look`).
    :param drop_after: the bridge's ``lockstep_timeout``: a longer silence is ``dropped``.
    """

    def __init__(self, names: Iterable[str], limit: float, notice: float = NOTICE,
                 drop_after: float = LOCKSTEP_TIMEOUT):
        """Watch the nodes ``names``; a participant is silent after ``limit`` wall seconds."""
        self.names = frozenset(names)
        self.limit = float(limit)
        self.notice = float(notice)
        self.drop_after = float(drop_after)
        self.reached: Dict[str, float] = {}  # participant -> newest sim time it answered
        self.heard: Dict[str, float] = {}    # participant -> wall time of that answer
        self.silences: List[Silence] = []    # every silence, oldest first
        self._open: Dict[str, Silence] = {}  # participant -> its silence going on

    def answer(self, name: str, sim_t: float, wall: float) -> None:
        """Take one answer of ``name``, at sim time ``sim_t`` (the end of time: it left)."""
        if name not in self.names:
            return
        silence = self._open.get(name)
        if silence is not None and name in self.heard and (
                sim_t > self.reached[name] or sim_t >= lockstep.END_OF_TIME.sec) and (
                wall - self.heard[name] > self.notice):  # (not a late node's next answer)
            self._measure(silence, wall - self.heard[name], 0.0)  # as long as its gap
        if sim_t >= lockstep.END_OF_TIME.sec:
            self.reached.pop(name, None)
            self.heard.pop(name, None)
            if silence is not None:
                self._open.pop(name).ended = True
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

    def _measure(self, silence: Silence, wall_s: float, lag_s: float) -> None:
        silence.wall_s = max(silence.wall_s, wall_s)
        silence.lag_s = max(silence.lag_s, lag_s)
        silence.dropped = silence.wall_s > self.drop_after or silence.lag_s > self.drop_after

    def look(self, sim_now: float, wall: float) -> List[Silence]:
        """Update :attr:`silences` now: begin, lengthen or end each one; return those going on.

        A participant is silent while it is behind the newest sim time and has not answered
        for ``notice`` wall seconds, or sim time is ``notice`` seconds beyond its answer.

        :param sim_now: the newest sim time the launcher has heard on ``/clock``, s.
        :param wall: now, s (the clock of :meth:`answer`'s ``wall``).
        """
        front = max([sim_now, *self.reached.values()])
        for name, t in self.reached.items():
            gap, lag = wall - self.heard[name], front - t
            if lag > 1e-6 and (gap > self.notice or lag > self.notice):
                silence = self._open.get(name)
                if silence is None:
                    silence = self._open[name] = Silence(name, t)
                    self.silences.append(silence)
                self._measure(silence, gap, lag)
            elif name in self._open:
                self._open.pop(name).ended = True
        return list(self._open.values())


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
