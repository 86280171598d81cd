"""The bridge's link to its neighbours in a line of cells (:mod:`scara_collab.core.line`).

A cell with a cell downstream (bridge parameter ``line_downstream``) hands on what passes the
end of its belt: with every clock, and every :data:`HEARTBEAT` wall seconds while its clock
stands (paused, waiting), it publishes ``line/handoff``
(:class:`~scara_collab.nodes.protocol.LineHandoff`: its frontier, its count, the handoffs of
the last seconds, the items on its belt). A cell with a cell upstream (``line_upstream``)
subscribes ``line/upstream``, which the launcher remaps to the upstream cell's
``line/handoff`` (``line/upstream:=/cell_0/line/handoff``), puts each item on its belt once, at
its arrival, and never steps past what the upstream frontier allows (:meth:`LineLink.limit`).
Names are relative, so a whole line moves with a namespace.

A cell with two cells upstream also subscribes ``line/upstream2`` (remapped to the handoffs of
the cell two places upstream) and keeps what it would need should the cell between die
(:class:`~scara_collab.core.line.Bypass`). When the cell upstream, once heard, stays silent
for ``line_timeout`` wall seconds while this cell waits for it, it is taken for dead: its
section becomes plain belt (the items on it ride to its end, the items handed to it ride all
through it) and the cell two places upstream becomes this cell's upstream. The first cell's
death leaves the items its belt carried; nothing more comes.

A malformed message is logged and dropped (the frontier it carries is not believed); a handoff
lost for longer than the repeat window is reported once per item as an error.
"""
import math
import time
from typing import Callable, Optional

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from scara_collab.core.line import Bypass, HandedOn, Inbox, Section
from scara_collab.graph import LINE_HANDOFF, LINE_UPSTREAM, LINE_UPSTREAM2
from scara_collab.nodes import protocol as proto
from scara_collab.nodes.guarded import guarded
from scara_collab.nodes.qos import EVENTS

HEARTBEAT = 0.5  # wall s: a cell hands on (its frontier again) at least this often


class LineLink:
    """Hand items on downstream and take them from upstream, for one bridge.

    :param node: the bridge node (publisher, subscription, logger).
    :param sim: the bridge's :class:`~scara_collab.sim.cell_sim.CellSim`.
    :param cell: this cell's index along the line (its own items are numbered from
        ``cell * 1_000_000 + 1``, so they never meet the ids handed on from upstream).
    :param upstream: a cell upstream hands items on to this one.
    :param downstream: a cell downstream takes the items that pass this belt's end.
    :param on_news: called when a message from upstream may let the cell step on.
    :param timeout: wall s of silence after which the cell upstream is taken for dead.
    """

    ID_BLOCK = 1_000_000

    def __init__(self, node: Node, sim, cell: int, upstream: bool, downstream: bool,
                 on_news: Callable[[], None], timeout: float = 5.0):
        """Join the line: the conveyor hands on (or misses) and numbers its items."""
        self.node, self.sim, self.cell = node, sim, int(cell)
        self.upstream, self.downstream = bool(upstream), bool(downstream)
        self.section = Section(sim.cell)
        self.handed_on = HandedOn()
        self.inbox = Inbox(self.section)
        self.bypass = Bypass(self.section)
        self.timeout = float(timeout)
        self.dead_upstream: Optional[str] = None  # why the cell upstream is taken for dead
        self._dead_since: Optional[float] = None  # monotonic s it was taken for dead
        #: wall s from the takeover to this cell's first item sorted after it (None: not yet)
        self.sorting_again: Optional[float] = None
        self._on_news = on_news
        self._lost_said = 0
        self._heard: Optional[float] = None  # monotonic s of the last message from upstream
        self._last: Optional[proto.LineHandoff] = None
        sim.conveyor.line.join(self.downstream, self.cell * self.ID_BLOCK + 1)
        self._pub = (node.create_publisher(DiagnosticStatus, LINE_HANDOFF, EVENTS)
                     if self.downstream else None)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        if self.downstream:  # a heartbeat: paused or waiting, the cell is alive
            node.create_timer(HEARTBEAT, guarded(node, lambda: self.publish(sim.time)),
                              clock=steady)
        if self.upstream:
            node.create_subscription(DiagnosticStatus, LINE_UPSTREAM,
                                     guarded(node, self._on_upstream), EVENTS)
            if self.cell >= 2:
                node.create_subscription(DiagnosticStatus, LINE_UPSTREAM2,
                                         guarded(node, self._on_upstream2), EVENTS)
            node.create_timer(HEARTBEAT, guarded(node, self._watch), clock=steady)

    @property
    def active(self) -> bool:
        """Return True in a line (a neighbour either side)."""
        return self.upstream or self.downstream

    def limit(self) -> float:
        """Return the latest sim time this cell may step to (infinity with no one upstream)."""
        if not self.upstream or (self.dead_upstream is not None and self.cell < 2):
            return math.inf
        return self.inbox.limit()

    def publish(self, frontier: float) -> None:
        """Hand on what passed the belt's end, with the frontier (called with each clock).

        The frontier is never later than the conveyor's last update: an item that crosses
        after it is found at the next one (the bridge may stop between two updates).
        """
        if self._pub is None:
            return
        frontier = min(frontier, self.sim.conveyor.checked)
        for h in self.sim.conveyor.line.pop_handoffs():
            self.handed_on.add(h)
        msg = proto.LineHandoff(self.cell, round(frontier, 9), self.handed_on.handed,
                                tuple(self.handed_on.message(frontier)),
                                tuple(self.sim.conveyor.line.on_belt()))
        self._pub.publish(msg.to_msg())

    def _parse(self, msg: DiagnosticStatus) -> Optional[proto.LineHandoff]:
        try:
            return proto.LineHandoff.from_msg(msg)
        except proto.ProtocolError as exc:
            self.node.get_logger().warning(f'line: dropped a malformed handoff message: {exc}')
            return None

    def _take(self, frontier: float, handoffs, handed: Optional[int], source: str) -> None:
        for h, at in self.inbox.offer(frontier, handoffs, handed):
            try:
                self.sim.conveyor.line.receive(h, at)
            except ValueError as exc:
                self.node.get_logger().error(f'line: item not taken from {source}: {exc}')
        if self.inbox.lost > self._lost_said:
            self.node.get_logger().error(
                f'line: {self.inbox.lost - self._lost_said} item(s) handed on by {source} '
                f'never arrived here (lost for longer than the {self.handed_on.window:g} s the '
                'handoff messages repeat)')
            self._lost_said = self.inbox.lost
        self._on_news()

    def _on_upstream(self, msg: DiagnosticStatus) -> None:
        m = self._parse(msg)
        if m is None:
            return
        self._heard = time.monotonic()
        if self.dead_upstream is not None:
            # it speaks again: what it hands on that is new still comes (by id, once)
            self._take(m.frontier, m.handoffs, None, f'cell {m.cell}')
            return
        self._last = m
        self.bypass.prune(m.frontier)
        self._take(m.frontier, m.handoffs, m.handed, f'cell {m.cell}')

    def _on_upstream2(self, msg: DiagnosticStatus) -> None:
        m = self._parse(msg)
        if m is None:
            return
        if self.dead_upstream is None:
            self.bypass.hear(m.handoffs)
            return
        frontier, through = self.bypass.relay(m.frontier, m.handoffs)
        self._take(frontier, through, None, f'cell {m.cell} through the dead section')

    def _watch(self) -> None:
        """Take the cell upstream for dead when it stays silent while this cell waits."""
        if self.dead_upstream is not None or self._heard is None:
            return
        silent = time.monotonic() - self._heard
        waiting = self.sim.time + self.sim.dt > self.inbox.limit() - 1e-9
        if silent < self.timeout or not waiting:
            return
        last = self._last
        frontier = last.frontier if last is not None else self.inbox.frontier
        self.dead_upstream = (f'cell {self.cell - 1} silent for {silent:.1f} s at its sim '
                              f't={frontier:.2f} s')
        belt = last.belt if last is not None else ()
        through = self.bypass.takeover(frontier, belt)
        self._dead_since = time.monotonic()
        self.node.get_logger().error(
            f'line: {self.dead_upstream}: taken for dead; its section is plain belt from '
            f'now on ({len(belt)} item(s) on it, {len(through) - len(belt)} on their way '
            f'into it)' + ('' if self.cell >= 2 else '; nothing more will come'))
        self._take(frontier, through, None, f'the dead cell {self.cell - 1}')

    def on_event(self, kind: str, item: int, t: float) -> None:
        """Take an item event of this cell: the first sort after a takeover is logged."""
        if kind != 'sorted' or self._dead_since is None or self.sorting_again is not None:
            return
        self.sorting_again = time.monotonic() - self._dead_since
        self.node.get_logger().warning(
            f'line: sorting again: item {item} sorted at sim t={t:.2f} s, '
            f'{self.sorting_again:.1f} s wall after cell {self.cell - 1} was taken for dead')

    def summary(self) -> str:
        """Return the cell's line counts, in words (for the bridge's last log line)."""
        dead = f'; {self.dead_upstream}' if self.dead_upstream else ''
        if self.sorting_again is not None:
            dead += f', sorting again {self.sorting_again:.1f} s wall after'
        return (f'line cell {self.cell}: {self.handed_on.handed} handed on, '
                f'{self.inbox.received} received ({self.inbox.repeats} repeats, '
                f'{self.inbox.lost} lost){dead}')
