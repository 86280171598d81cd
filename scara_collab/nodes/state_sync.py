"""A node's periodic decision at sim time T, taken on the joint state stamped T.

The bridge sends the joint state of T right after the ``/clock`` of T (and the one of
T - 10 ms just before it), on another topic, and a node takes them in either order. A tick run
straight from the clock would decide on the state of T - 10 ms or of T - 20 ms, as they come,
and two runs of the same seed would part. :class:`StateSync` holds the tick until the state of
its instant is in, and the node's lockstep answer with it (the bridge cannot step on in the
meantime), unless the states have stopped coming; in real time (``enabled`` false) the tick
decides on the newest state at once.
"""
from typing import Callable, Optional


class StateSync:
    """Run ``decide()`` for each tick once the joint state of the tick's instant is in.

    :param decide: the tick's work.
    :param state_period: s between joint states (``1 / state_rate``).
    :param enabled: wait for the state at all (lockstep); else decide at once.
    :ivar lockstep: the node's lockstep participant (set once it has joined; None: none).
    """

    def __init__(self, decide: Callable[[], None], state_period: float, enabled: bool = True):
        """No state yet, no tick waiting."""
        self.decide, self.state_period, self.enabled = decide, float(state_period), enabled
        self.lockstep = None
        self.state_time = float('-inf')  # sim s of the newest joint state
        self._due: Optional[float] = None  # a tick waiting for the state of its instant

    def on_tick(self, now: float) -> None:
        """Take the tick at sim time ``now``: decide, or wait for the state of ``now``."""
        if self._due is not None:  # the state a tick waited for never came: decide on the last
            self._decide_due()
        if (self.lockstep is not None and self.enabled
                and now - 2 * self.state_period - 1e-6 <= self.state_time < now - 1e-9):
            self._due = now  # the state of this instant is on its way: decide on it
            self.lockstep.await_reply(('state', self._due))
            return
        self.decide()

    def on_state(self, stamp: float) -> None:
        """Take a joint state stamped ``stamp`` (admitted by the node); run a tick it completes."""
        self.state_time = float(stamp)
        if self._due is not None and self.state_time >= self._due - 1e-9:
            self._decide_due()

    def _decide_due(self) -> None:
        key, self._due = ('state', self._due), None
        self.decide()
        self.lockstep.reply(key)
