"""The separation monitor's decision at a scan instant, taken on that instant's inputs.

At each scan instant T the bridge sends the arms' safety state, their planned velocity and
every scanner's scan of T, then the ``/clock`` of T. They travel on four topics and the
middleware does not keep their order across topics: a large message (a scan, a joint state)
and the small ``/clock`` reach a node by different paths, and the clock can come first. A
decision run straight from the clock then weighs the scans of T or of T - 40 ms as they come,
the arms' speed factors change one clock earlier or later, and two runs of the same seed part
(docs/realtime.md, *Repeatable runs*).

:class:`ScanSync` holds the decision of a scan instant (and the node's lockstep answer with it:
the bridge cannot step on meanwhile) until every input that came at the previous scan instant
has come for this one too. The inputs named at the start count as come at sim time 0 (the
bridge's first scans go out before the graph runs), so the first scan instant waits for them
too. An input silent at the previous instant is not waited for (a silent scanner is the
monitor's to judge, not to wait for); one that stops now is waited for once, at most
:data:`scara_collab.nodes.lockstep.REPLY_WAIT` wall seconds. In real time (``enabled`` false)
the clock waits for nobody and the decision runs at once, as the inputs have come.

It assumes the lockstep's window is one clock period (the bridge's ``lockstep_window``
default): the bridge then stands at a scan instant until the decision there is taken, and an
input of the next scan instant cannot come first. A wait that runs out (an input that stopped,
or one the node refused without saying so) costs ``REPLY_WAIT`` wall seconds and the run's
repeatability; the node therefore hands every input it refuses to :meth:`ScanSync.on_input`
too, as come.
"""
from typing import Callable, Dict, Hashable, Iterable, Optional

#: ns: a stamp within this of a scan instant is of that instant
ON_GRID = 100_000


class ScanSync:
    """Run ``decide()`` at each tick, at a scan instant once that instant's inputs are in.

    :param decide: the decision's work.
    :param period: s between scan instants (the scanners' period; instants at its multiples).
    :param enabled: wait for the inputs at all (lockstep); else decide at once.
    :param inputs: the inputs expected from the start (counted as come at sim time 0).
    :ivar lockstep: the node's lockstep participant (set once it has joined; None: none).
    """

    def __init__(self, decide: Callable[[], None], period: float, enabled: bool = True,
                 inputs: Iterable[Hashable] = ()):
        """Count the ``inputs`` as come at instant 0; no decision waiting."""
        if not period > 0:
            raise ValueError(f'scan period must be > 0 s, got {period}')
        self.decide, self.enabled = decide, bool(enabled)
        self.period_ns = int(round(period * 1e9))
        self.lockstep = None
        # input -> the newest scan instant it came at
        self.seen: Dict[Hashable, int] = {name: 0 for name in inputs}
        self.due: Optional[int] = None  # the scan instant whose decision waits for its inputs

    def instant(self, ns: int) -> Optional[int]:
        """Return the index of the scan instant at ``ns`` (nanoseconds), or None if off the grid.

        >>> s = ScanSync(lambda: None, 0.04)
        >>> s.instant(80_000_000), s.instant(80_000_001), s.instant(100_000_000)
        (2, 2, None)
        """
        k = (ns + self.period_ns // 2) // self.period_ns
        return k if abs(ns - k * self.period_ns) <= ON_GRID else None

    def missing(self, k: int) -> list:
        """Return the inputs that came at scan instant ``k - 1`` and not yet at ``k``."""
        return sorted((str(s) for s, seen in self.seen.items() if seen == k - 1))

    def on_input(self, source: Hashable, stamp_ns: int) -> None:
        """Take an input of ``source`` stamped ``stamp_ns``; run a decision it completes."""
        k = self.instant(stamp_ns)
        if k is None:
            return
        if k > self.seen.get(source, -1):
            self.seen[source] = k
        if self.due is not None and not self.missing(self.due):
            self._decide_due()

    def on_tick(self, now_ns: int) -> None:
        """Take the tick at sim time ``now_ns``: decide, or wait for the inputs of its instant."""
        if self.due is not None:  # the inputs a decision waited for never came: decide on it
            self._decide_due()
        k = self.instant(now_ns)
        if (self.enabled and self.lockstep is not None and k is not None
                and self.missing(k)):
            self.due = k
            self.lockstep.await_reply(('scan', k))
            return
        self.decide()

    def _decide_due(self) -> None:
        key, self.due = ('scan', self.due), None
        try:
            self.decide()
        finally:  # a decision that failed (logged by the node) must not hold sim time 2 s
            self.lockstep.reply(key)
