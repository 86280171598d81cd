"""A line of cells along one belt: sections, handoffs, and the frontier between cells.

Where the sections lie, what crosses between them, and how far a cell may run ahead of the one
upstream. No ROS here.

Cell ``k`` of a line simulates its own section of the belt (``x_start`` to ``x_end`` in its own
frame, the cell's usual one) in its own world; its frame sits ``k * pitch`` along the line.
The pitch keeps the arms of neighbouring cells apart at full reach (:func:`min_pitch`), so no
cell needs the other's arms for its collision checks. Between two sections the item rides a
gap of ``pitch - (x_end - x_start)`` metres, which takes :attr:`Section.transit` seconds.

**Handoff.** An item carried past ``x_end`` of cell ``k`` is *handed on*
(:class:`Handoff`: its id, class, lateral position and the sim time it crossed); cell ``k + 1``
puts it on its belt at ``x_start`` one transit later (:meth:`Section.arrival`), same id, same
class, same ``y``. The last cell has no one to hand on to: there the item is missed.

**Time between cells: conservative synchronisation.** Each cell keeps its own clock (and its
own lockstep). A cell publishes, with its handoffs, its *frontier*: the sim time up to which
every handoff it will ever make is in the message or an earlier one. An item that crosses
after the frontier ``F`` arrives downstream after ``F + transit``, so the cell downstream may
step up to that time and no further (:meth:`Inbox.limit`): it can never pass an arrival it has
not been told of. Nothing else waits for anything: the cells run in parallel, on any cores
or machines, and a cell's log depends only on its seed and what it was handed, so the same
seed gives the same line log.

**Lost, late and repeated messages.** Every message repeats the handoffs of the last
:attr:`HandedOn.window` seconds before its frontier, so a lost message is made up for by the next
one; the inbox takes an item once, by id (:meth:`Inbox.offer`), so repeats change nothing.
Each message also carries the number of items handed on up to its frontier, so a downstream
cell that missed one for longer than the window knows it (:attr:`Inbox.lost`).

**A cell that dies.** Each message also says which items rest on the sender's belt at its
frontier. The cell two places downstream of a cell that dies has listened to the cell before it
all along (:class:`Bypass`). When the cell between falls silent, the belt of the dead section
still carries: the items on its belt at its last frontier ride to its end, the items handed to
it after that ride all through it, and from then on the cell before the dead one is this
cell's upstream, one section further away (:meth:`Bypass.takeover`, :meth:`Bypass.relay`).

>>> from scara_collab.core.model import load_cell
>>> cell = load_cell()
>>> round(min_pitch(cell), 3)
5.2
>>> s = Section(cell)
>>> round(s.gap, 3), round(s.transit, 3)
(0.2, 1.0)
>>> box = Inbox(s)
>>> [(h.item, round(t, 3)) for h, t in box.offer(10.0, [Handoff(7, 'red', 0.1, 9.5)], 1)]
[(7, 10.5)]
>>> round(box.limit(), 9)  # the cell may step to the frontier plus the transit
11.0
>>> box.offer(10.02, [Handoff(7, 'red', 0.1, 9.5)], handed=1)  # a repeat: nothing new
[]
"""
from dataclasses import dataclass
import math
from typing import Dict, Iterable, List, Optional, Tuple

from scara_collab.core.model import CellModel


@dataclass(frozen=True)
class Handoff:
    """An item that left a section at its end, as the next section receives it.

    :ivar item: id (kept along the line); :ivar cls: class; :ivar y: lateral position, m
        (world of either cell: the cells' frames differ along x only);
    :ivar time: sim time it crossed ``x_end``, s.
    """

    item: int
    cls: str
    y: float
    time: float


def arm_extent(cell: CellModel) -> Tuple[float, float]:
    """Return the x range (cell frame, m) any part of either arm can reach, at full reach.

    Each arm sweeps at most a disc of radius ``l1 + l2`` plus its link radius about its base.
    """
    lo = [a.base[0, 3] - (a.l1 + a.l2 + max(a.link_radius, a.quill_radius)) for a in cell.arms]
    hi = [a.base[0, 3] + (a.l1 + a.l2 + max(a.link_radius, a.quill_radius)) for a in cell.arms]
    return float(min(lo)), float(max(hi))


def min_pitch(cell: CellModel) -> float:
    """Return the least distance between neighbouring cells' frames, m.

    At that pitch the arms of neighbouring cells, both at full reach towards each other, are
    ``safety_margin`` apart, and no section's belt overlaps the next one's.
    """
    lo, hi = arm_extent(cell)
    belt = cell.belt
    return max(hi - lo + cell.safety_margin, belt.x_end - belt.x_start)


class Section:
    """One cell's section of the line: its pitch, the gap after it and the transit over it.

    :param cell: the cell model (every cell of a line has the same one).
    :param pitch: m between neighbouring cells' frames; default :func:`min_pitch`.
    :raises ValueError: a pitch below :func:`min_pitch` (arms of neighbours could meet) or
        a belt that does not carry items downstream (speed <= 0).
    """

    def __init__(self, cell: CellModel, pitch: Optional[float] = None):
        """Check the pitch against the cell's reach."""
        least = min_pitch(cell)
        self.pitch = least if pitch is None else float(pitch)
        if not (math.isfinite(self.pitch) and self.pitch >= least - 1e-9):
            raise ValueError(f'line pitch {pitch!r} m is below {least:.3f} m: the arms of '
                             'neighbouring cells could come closer than the safety margin')
        belt = cell.belt
        if not belt.speed > 0:
            raise ValueError(f'a line needs a belt carrying items along +x, speed {belt.speed}')
        self.belt = belt
        self.gap = self.pitch - (belt.x_end - belt.x_start)
        self.transit = self.gap / belt.speed

    def arrival(self, h: Handoff) -> float:
        """Return the sim time the item reaches the next section's ``x_start``."""
        return h.time + self.transit

    def offset(self, k: int) -> float:
        """Return where cell ``k``'s frame sits along the line, m."""
        return k * self.pitch


class HandedOn:
    """The handoffs a cell has made, the last :attr:`window` seconds of them repeated.

    :param window: s of handoffs each message repeats (they make up for lost messages).
    """

    def __init__(self, window: float = 2.0):
        """Nothing handed on yet."""
        self.window = float(window)
        self.handed = 0
        self._recent: List[Handoff] = []

    def add(self, h: Handoff) -> None:
        """Hand ``h`` on (in crossing order)."""
        self._recent.append(h)
        self.handed += 1

    def message(self, frontier: float) -> List[Handoff]:
        """Return the handoffs to send with ``frontier``: those of the last window before it."""
        self._recent = [h for h in self._recent if h.time > frontier - self.window]
        return list(self._recent)


class Inbox:
    """What a cell has been handed by the cell upstream, each item once.

    :param section: the upstream cell's section (its transit).
    """

    def __init__(self, section: Section):
        """Nothing heard yet: :meth:`limit` is minus infinity (no step allowed)."""
        self.section = section
        self.frontier = -math.inf
        self.received = 0
        self.repeats = 0
        self.lost = 0  # handed on upstream by the frontier, never heard here
        self._seen: set = set()

    def offer(self, frontier: float, handoffs: Iterable[Handoff],
              handed: Optional[int] = None) -> List[Tuple[Handoff, float]]:
        """Take a message: its frontier, its handoffs and the upstream count.

        :return: the items not taken before, each with its arrival time at ``x_start``, in
            arrival order (ties by id), so a cell puts them on its belt the same way in every
            run. Items already taken are repeats and change nothing; an older frontier (a late
            message) does not move the limit back. ``handed`` (the sender's count) finds
            items lost for good; None where the sender cannot count them (a bypass).
        """
        new = []
        for h in handoffs:
            if h.item in self._seen:
                self.repeats += 1
                continue
            self._seen.add(h.item)
            new.append((h, self.section.arrival(h)))
        self.received += len(new)
        if frontier > self.frontier:
            self.frontier = float(frontier)
            if handed is not None:
                self.lost = max(0, int(handed) - self.received)
        return sorted(new, key=lambda v: (v[1], v[0].item))

    def limit(self) -> float:
        """Return the latest sim time the cell may step to: the frontier plus the transit."""
        return self.frontier + self.section.transit


@dataclass(frozen=True)
class OnBelt:
    """An item resting on a section's belt at a frontier: id, class and place (cell frame)."""

    item: int
    cls: str
    x: float
    y: float


class Bypass:
    """Carry on when the cell upstream dies: its section becomes plain belt.

    Fed with the messages of the cell two places upstream (:meth:`hear`) and the frontier of
    the one between (:meth:`prune`), it keeps the items handed to the cell between that had
    not reached its belt by its frontier. :meth:`takeover` turns the dead cell's last
    belt and those items into the handoffs it would have made; :meth:`relay` does the same
    for what the cell two places upstream hands on afterwards.

    >>> from scara_collab.core.model import load_cell
    >>> s = Section(load_cell())
    >>> b = Bypass(s)
    >>> b.hear([Handoff(5, 'red', 0.0, 19.5)])
    >>> b.prune(10.0)  # the cell between is at t=10 s: item 5 has not reached it
    >>> [(h.item, round(h.time, 3)) for h in b.takeover(10.0, [OnBelt(4, 'blue', 3.5, 0.1)])]
    [(4, 15.0), (5, 45.5)]
    >>> fr, hs = b.relay(21.0, [Handoff(6, 'red', 0.2, 20.8)])
    >>> round(fr, 3), [(h.item, round(h.time, 3)) for h in hs]
    (47.0, [(6, 46.8)])
    """

    def __init__(self, section: Section):
        """Nothing heard from two places upstream yet."""
        self.section = section
        self.across = (section.belt.x_end - section.belt.x_start) / section.belt.speed
        self.pending: Dict[int, Handoff] = {}
        self.dead = False

    def _through(self, h: Handoff) -> Handoff:
        """Return ``h`` (crossing two places upstream) as it crosses the dead section's end."""
        return Handoff(h.item, h.cls, h.y, h.time + self.section.transit + self.across)

    def hear(self, handoffs: Iterable[Handoff]) -> None:
        """Keep what the cell two places upstream hands on (while the one between lives)."""
        for h in handoffs:
            self.pending.setdefault(h.item, h)

    def prune(self, upstream_frontier: float) -> None:
        """Forget the items the cell between has had on its belt by its frontier."""
        self.pending = {i: h for i, h in self.pending.items()
                        if h.time + self.section.transit > upstream_frontier}

    def takeover(self, upstream_frontier: float, belt: Iterable[OnBelt]) -> List[Handoff]:
        """Return the handoffs the dead cell's plain belt makes, in time order.

        The items on its belt at its last frontier ride to its end; the items handed to it
        after that ride all through it.
        """
        self.dead = True
        speed, end = self.section.belt.speed, self.section.belt.x_end
        out = [Handoff(b.item, b.cls, b.y, upstream_frontier + max(0.0, end - b.x) / speed)
               for b in belt]
        out += [self._through(h) for h in self.pending.values()]
        self.pending = {}
        return sorted(out, key=lambda h: (h.time, h.item))

    def relay(self, frontier: float, handoffs: Iterable[Handoff]) -> Tuple[float, List[Handoff]]:
        """Return a message of the cell two upstream as the dead section's: frontier, handoffs."""
        return (frontier + self.section.transit + self.across,
                [self._through(h) for h in handoffs])


class Share:
    """Which of the items reaching cell ``k`` of a line of ``cells`` it takes.

    The rule, from the picking lines (a FANUC line gives each of three robots a third of the
    items; a PickMaster line hands them out so the flow left downstream stays even):

    - **below saturation** the line's load is even: cell ``k`` takes ``1 / (cells - k)`` of
      the items that reach it (the first of three a third, the second half of what is left,
      the last all of it), chosen evenly in the order they come (:meth:`see`);
    - **at saturation**, when its share of the items reaching it per minute is at least what
      it can sort (``capacity``, items/min), the cell takes what it can, by its own cheapest
      cycle: it leaves nothing on purpose;
    - the last cell never leaves an item.

    Within what it takes, the job's own rules pick as in a lone cell (the urgent item first).

    >>> share = Share(0, 3, capacity=40.0)
    >>> share.see([1, 2, 3, 4, 5, 6], now=0.0)
    >>> [share.takes(i, now=1.0) for i in range(1, 7)]
    [False, False, True, False, False, True]
    """

    #: s of arrivals the rate is measured over
    WINDOW = 60.0
    #: s of arrivals needed before the rate is believed (until then: not saturated)
    SETTLE = 10.0

    def __init__(self, k: int, cells: int, capacity: float):
        """Take ``1 / (cells - k)``; ``capacity``: one cell's items/min at saturation."""
        if not 0 <= k < cells:
            raise ValueError(f'cell {k} is not in a line of {cells}')
        self.share = 1.0 / (cells - k)
        self.capacity = float(capacity)
        self.decided: Dict[int, bool] = {}
        self._arrivals: List[float] = []
        self._first: Optional[float] = None
        self._acc = 0.0

    def see(self, items: Iterable[int], now: float) -> None:
        """Note the items seen now; each new one is taken or left, evenly (in id order)."""
        for item in sorted(items):
            if item in self.decided:
                continue
            self._acc += self.share
            self.decided[item] = self._acc >= 1.0 - 1e-9
            if self.decided[item]:
                self._acc -= 1.0
            self._arrivals.append(now)
            if self._first is None:
                self._first = now

    def rate(self, now: float) -> Optional[float]:
        """Return the items reaching the cell per minute (the last minute), None too early."""
        if self._first is None or now - self._first < self.SETTLE:
            return None
        self._arrivals = [t for t in self._arrivals if t > now - self.WINDOW]
        return len(self._arrivals) * 60.0 / min(self.WINDOW, now - self._first)

    def saturated(self, now: float) -> bool:
        """Return True if the cell's share of what reaches it is more than it can sort."""
        rate = self.rate(now)
        return rate is not None and rate * self.share >= self.capacity

    def takes(self, item: int, now: float) -> bool:
        """Return True if the cell may take ``item`` now."""
        return self.share >= 1.0 or self.decided.get(item, True) or self.saturated(now)
