"""The simulated conveyor: the belt, the item feed, the items, the bins and the item events.

:class:`Conveyor` lives in the PyBullet world of a :class:`~scara_collab.sim.cell_sim.CellSim`
(same client, same clock) and knows nothing of the arms but their body (to name what knocked
an item off the belt). The belt is a frictionless static box with the URDF conveyor's
collision geometry (:class:`BeltBox`; the URDF link keeps only its visual): an item on it keeps its
velocity exactly, and :meth:`Conveyor.update` re-imposes the belt velocity ``(speed, 0, 0)``
on every item resting on the belt (after a push, a release onto the belt, a collision).

Events, checked at every update: ``missed`` (an item on the belt passes ``x_end``, removed;
``handed_on`` instead in a cell of a line with a cell downstream), ``sorted`` / ``wrong_bin``
(an item at rest inside a bin, removed; the event names the bin's robot), ``dropped`` (at rest
on the floor, removed), plus ``spawned`` as it happens and ``received`` as an item handed on by
the cell upstream comes onto the belt; the gripper adds ``grasped`` and ``released``
(:meth:`Conveyor.event`).

In a line of cells the belt is one section of the line: what comes onto it from the cell
upstream and what it hands on to the cell downstream is its :class:`SectionEnds`
(:attr:`Conveyor.line`: :meth:`SectionEnds.join`, :meth:`SectionEnds.receive`,
:meth:`SectionEnds.pop_handoffs`).
"""
from dataclasses import dataclass
import math
from typing import Callable, Dict, List, NamedTuple, Optional, Tuple

import numpy as np
import pybullet

from scara_collab.core.config import ConfigError
from scara_collab.core.line import Handoff, OnBelt
from scara_collab.core.model import CellModel
from scara_collab.core.palette import class_colour
from scara_collab.core.sorting import on_belt

FEED_PATTERNS = ('random', 'mirror_pairs')
PAYLOAD_CLASS = 'payload'
"""Class of the test bodies hung on a tool (``Grippers.attach_payload``), not sortable."""

_LOST_Z = -1.0  # m, an item below this fell through something: dropped
INLET_GAP = 0.002  # m between an item handed on and the one ahead of it, if they came close


@dataclass(frozen=True)
class Item:
    """One item as :meth:`Conveyor.items` reports it.

    :ivar id: item id (unique over the run); :ivar cls: item class;
    :ivar position: ``(3,)`` centre in world, m; :ivar velocity: ``(3,)`` m/s;
    :ivar state: ``'belt'`` (resting on the belt, carried), ``'held'`` (in a gripper) or
        ``'free'`` (anything else: falling, in a bin, on the floor).
    """

    id: int
    cls: str
    position: np.ndarray
    velocity: np.ndarray
    state: str


@dataclass(frozen=True)
class SimEvent:
    """Something that happened to an item.

    :ivar time: sim time, s; :ivar kind: one of
        :data:`~scara_collab.core.sorting.ITEM_EVENTS`; :ivar item: item id;
    :ivar cls: item class; :ivar robot: the arm involved (gripper, bin, last holder of a
        dropped item) or ``''``; :ivar cause: for an item that left the belt without a
        grasp (``dropped``, ``missed`` after a push), what touched it last, else ``''``.
    """

    time: float
    kind: str
    item: int
    cls: str
    robot: str = ''
    cause: str = ''


class BeltBox(NamedTuple):
    """The belt's collision box: centre, orientation and half extents.

    :ivar position: centre in world, m; :ivar orientation: quaternion ``(x, y, z, w)``;
    :ivar half_extents: m.
    """

    position: Tuple[float, float, float]
    orientation: Tuple[float, float, float, float]
    half_extents: Tuple[float, float, float]


class Bin(NamedTuple):
    """A bin's opening: who it belongs to, what it takes, and the box an item rests in."""

    robot: str
    cls: str
    x: float          # centre, world, m
    y: float
    half_x: float     # half the inner size, m
    half_y: float
    top: float        # an item below this height (its centre) is inside, m


class ItemRecord:
    """Mutable bookkeeping of one item: its body, state and who holds or held it."""

    __slots__ = ('id', 'body', 'cls', 'mass', 'state', 'holder', 'constraint', 'last_robot',
                 'cause')

    def __init__(self, item_id: int, body: int, cls: str, mass: float, state: str):
        """Record item ``item_id`` (PyBullet ``body``) of class ``cls`` in ``state``."""
        self.id, self.body, self.cls, self.mass, self.state = item_id, body, cls, mass, state
        self.holder: Optional[str] = None      # the robot holding it
        self.constraint: Optional[int] = None  # the gripper's fixed constraint
        self.last_robot = ''
        self.cause = ''  # what knocked it off the belt (it was never grasped)


def build_belt(pb, belt: BeltBox) -> int:
    """Build the belt as a static, frictionless rigid box; return its PyBullet body."""
    box = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=list(belt.half_extents))
    body = pb.createMultiBody(0.0, box, -1, list(belt.position), list(belt.orientation),
                              useMaximalCoordinates=True)
    pb.changeDynamics(body, -1, lateralFriction=0.0, rollingFriction=0.0, spinningFriction=0.0)
    return body


class Feed:
    """The automatic feed: how often items come, in which pattern, and when they are due.

    >>> feed = Feed(2.0, 'mirror_pairs', now=0.0)
    >>> feed.period, feed.due(3.9), feed.due(4.0), feed.next
    (4.0, False, True, 8.0)
    """

    def __init__(self, interval: float, pattern: str, now: float):
        """Feed from ``now`` on (``interval`` s per item, 0: none): the first one period later."""
        self.interval, self.pattern = 0.0, 'random'
        self.set(interval, pattern, now)

    def set(self, interval: Optional[float], pattern: Optional[str], now: float) -> None:
        """Change the feed (None: keep that part); the next items come one period from ``now``.

        :param interval: s of sim time between items, ``0`` = no automatic feed.
        :param pattern: ``'random'`` (one item, random class and lateral offset) or
            ``'mirror_pairs'`` (two items of one class at ``y`` and ``-y`` about the belt
            centre line, same ``x``).
        :raises ValueError: for a negative or non-finite interval or an unknown pattern.
        """
        if interval is not None:
            if not (math.isfinite(interval) and interval >= 0):
                raise ValueError(f'feed interval must be a number >= 0, got {interval!r}')
            self.interval = float(interval)
        if pattern is not None:
            if pattern not in FEED_PATTERNS:
                raise ValueError(f'feed pattern must be one of {FEED_PATTERNS}, got {pattern!r}')
            self.pattern = pattern
        self.next = now + self.period

    @property
    def period(self) -> float:
        """Return the seconds between feeds.

        ``interval`` is per item, so mirror pairs (two items) come every two intervals and
        every pattern delivers the same items per minute.
        """
        return self.interval * (2.0 if self.pattern == 'mirror_pairs' else 1.0)

    def due(self, now: float) -> bool:
        """Return True if items are due at ``now`` (then the next ones are one period later)."""
        if self.interval > 0 and now >= self.next - 1e-9:
            self.next += self.period
            return True
        return False


def behind(x: float, y: float, boxes, half: float, gap: float = INLET_GAP) -> float:
    """Return ``x``, or less: where an item coming on at ``y`` overlaps none of ``boxes``.

    Items handed on arrive as far apart as their centres crossed the boundary; two that
    touched upstream, one turned or nudged, can cross closer than an item's size. Put one into
    the other and the simulator pushes them apart, one off the belt. It comes on behind the
    item in its way, ``gap`` apart, as it would on a real belt.

    :param boxes: ``(lo, hi)`` corners of the items on the belt (PyBullet's ``getAABB``).
    :param half: half the item's size.

    >>> round(behind(0.05, 0.0, [((0.0, -0.05, 0.2), (0.1, 0.05, 0.3))], 0.05, 0.002), 6)
    -0.052
    >>> behind(0.05, 0.2, [((0.0, -0.05, 0.2), (0.1, 0.05, 0.3))], 0.05, 0.002)
    0.05
    """
    moved = True
    while moved:
        moved = False
        for lo, hi in boxes:
            if (lo[0] - half - gap < x < hi[0] + half + gap
                    and lo[1] - half - gap < y < hi[1] + half + gap):
                x, moved = lo[0] - half - gap, True
    return x


class SectionEnds:
    """The belt as a section of a line of cells: items handed in, items handed on.

    The conveyor owns one (:attr:`Conveyor.line`) and calls it at each update: an item handed
    in by the cell upstream comes onto the belt at ``x_start`` (:meth:`arrive`), an item that
    passes ``x_end`` is handed on to the cell downstream or missed (:meth:`crossed`). Alone (not
    in a line) nothing comes in and everything that passes the end is missed.

    :param conveyor: the belt whose items it puts on and reads (its cell, records, poses).
    :ivar hand_on: a cell downstream takes what passes ``x_end`` (else it is missed).
    """

    def __init__(self, conveyor: 'Conveyor'):
        """Not in a line: nothing comes on, nothing is handed on."""
        self.conveyor = conveyor
        self.cell = conveyor.cell
        self.hand_on = False
        self.handed: List[Handoff] = []
        self._arriving: List[Tuple[float, Handoff]] = []  # (arrival at x_start, item)

    def join(self, hand_on: bool, first_id: int = 1) -> None:
        """Make the belt a section of a line (:mod:`scara_collab.core.line`).

        :param hand_on: a cell downstream takes the items that pass ``x_end``
            (:meth:`pop_handoffs`), instead of their being missed.
        :param first_id: the id of this cell's first own item (the automatic feed, a spawn
            service), so that its ids never meet those handed on from upstream.
        """
        self.hand_on = bool(hand_on)
        self.conveyor.number_from(first_id)

    def receive(self, h: Handoff, at: float) -> None:
        """Put the item ``h`` on the belt at ``x_start`` at sim time ``at`` (or now, if later).

        It comes on at the first update at or after ``at``, as far along the belt as it rode
        since then, with its id, class and lateral position: event ``received``.

        :raises ValueError: an unknown class, a lateral position off the belt, or an id this
            belt already has.
        """
        self.expect(h, at, lambda item: item in self.conveyor.records)

    def expect(self, h: Handoff, at: float, known: Callable[[int], bool]) -> None:
        """Take the item ``h`` to come on at ``x_start`` at sim time ``at``.

        :param known: tells if the belt has an item of that id already.
        :raises ValueError: an unknown class, a lateral position off the belt, or an id the
            belt already has (or expects).
        """
        if h.cls not in self.cell.item_classes:
            raise ValueError(f'handed item {h.item}: unknown class {h.cls!r}')
        # an item pushed towards an edge still rides the belt while its centre is on it
        if abs(h.y - self.cell.belt.centre_y) > self.cell.belt.width / 2.0 + 1e-9:
            raise ValueError(f'handed item {h.item}: y={h.y:.3f} is off the belt')
        if known(h.item) or any(h.item == a.item for _, a in self._arriving):
            raise ValueError(f'handed item {h.item}: already on this belt')
        self._arriving.append((float(at), h))

    def arrive(self, now: float) -> None:
        """Put on the belt the items handed in that come on by ``now`` (:meth:`arrivals`)."""
        conveyor = self.conveyor
        for h, x in self.arrivals(now, conveyor.belt_boxes):
            conveyor.place(h.cls, x, h.y, 'received', item_id=h.item)

    def arrivals(self, now: float, boxes: Callable[[], list]) -> List[Tuple[Handoff, float]]:
        """Return the items that come on by ``now``, in order, each with its ``x``; forget them.

        An item comes on as far along as it rode since it crossed, or behind the item in its
        way (:func:`behind`); if that is not on the belt yet, it stays due for a later call.

        :param boxes: returns the axis-aligned boxes ``(lo, hi)`` of the items on the belt.
        """
        if not self._arriving:  # the usual case, at every belt update
            return []
        due = sorted((a for a in self._arriving if a[0] <= now + 1e-9),
                     key=lambda a: (a[0], a[1].item))
        if not due:
            return []
        belt, half = self.cell.belt, self.cell.item_size / 2.0
        taken, placed, around = set(), [], boxes()
        for at, h in due:
            x = behind(min(belt.x_start + (now - at) * belt.speed, belt.x_end), h.y, around,
                       half)
            if x >= belt.x_start:
                taken.add(h.item)
                placed.append((h, x))
                around.append(((x - half, h.y - half), (x + half, h.y + half)))
        self._arriving = [a for a in self._arriving if a[1].item not in taken]
        return placed

    def crossed(self, rec: 'ItemRecord', x: float, y: float, now: float) -> str:
        """Take the belt item ``rec``, at ``(x, y)`` past ``x_end`` now; return its event.

        ``handed_on`` (kept for :meth:`pop_handoffs`, with the time it crossed) with a cell
        downstream, else ``missed``.
        """
        if not self.hand_on:
            return 'missed'
        belt = self.cell.belt
        self.handed.append(Handoff(rec.id, rec.cls, float(y), now - (x - belt.x_end) / belt.speed))
        return 'handed_on'

    def pop_handoffs(self) -> List[Handoff]:
        """Return the items handed on since the last call, in crossing order."""
        out, self.handed = self.handed, []
        return out

    def on_belt(self) -> List[OnBelt]:
        """Return the items resting on the belt now (what it carries on if the cell dies)."""
        return [OnBelt(rec.id, rec.cls, float(x), float(y))
                for rec, (x, y, _) in self.conveyor.resting()]


class Conveyor:
    """The belt, its feed, the items on it and the bins, in a PyBullet world.

    :param pb: the simulator's PyBullet client.
    :param cell: the cell model (belt, item size, classes, bins).
    :param sim_cfg: ``simulation.yaml`` (feed, jitter, inlet margin, rest speed).
    :param clock: returns the sim time, s.
    :param cell_body: the cell's URDF body (the arms), whose links are named by ``link_names``.
    :param belt_box: the URDF conveyor's collision box, built here as a frictionless body.
    :param seed: the item RNG seed (classes, lateral offsets).
    :raises ConfigError: if ``lateral_jitter`` puts items off the belt.
    """

    def __init__(self, pb, cell: CellModel, sim_cfg: dict, clock: Callable[[], float],
                 cell_body: int, belt_box: BeltBox, link_names: Dict[int, str], seed: int):
        """Build the belt box and the item shape; no items, the feed as configured."""
        belt, size = cell.belt, cell.item_size
        self._half_free = belt.width / 2.0 - size / 2.0
        if float(sim_cfg['lateral_jitter']) > self._half_free + 1e-9:
            raise ConfigError(f'simulation.yaml: lateral_jitter {sim_cfg["lateral_jitter"]} m '
                              f'puts items off the {belt.width} m belt (at most '
                              f'{self._half_free} m)')
        self._pb, self.cell, self.cfg, self._clock = pb, cell, sim_cfg, clock
        self._cell_body, self._link_names = cell_body, link_names
        self._rng = np.random.default_rng(int(seed))
        self.belt_body = build_belt(pb, belt_box)
        self._item_shape = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[size / 2] * 3)
        self._item_visual: Dict[str, int] = {}
        inner = cell.config['bins']['size']
        self.bins = [Bin(robot, cls, float(p[0]), float(p[1]), inner[0] / 2.0, inner[1] / 2.0,
                         float(p[2]) + inner[2] + size)
                     for (robot, cls), p in cell.bins.items()]
        self.records: Dict[int, ItemRecord] = {}
        self._next_id = 1
        self.checked = clock()  # sim time of the last update: every crossing by then is known
        self.line = SectionEnds(self)  # in a line of cells: what comes on, what is handed on
        self._events: List[SimEvent] = []
        self._get_pose = pb.getBasePositionAndOrientation
        self._get_vel = pb.getBaseVelocity
        self._set_vel = pb.resetBaseVelocity
        self.feed = Feed(float(sim_cfg['feed_interval']), sim_cfg['feed_pattern'], clock())

    # --- the feed -------------------------------------------------------------------------
    def set_feed(self, interval: Optional[float] = None, pattern: Optional[str] = None) -> None:
        """Change the automatic feed from now on (:meth:`Feed.set`)."""
        self.feed.set(interval, pattern, self._clock())

    def _feed(self) -> None:
        if self.feed.pattern == 'random':
            self.spawn_item()
            return
        classes = self.cell.item_classes
        cls = classes[int(self._rng.integers(len(classes)))]
        size = self.cell.item_size
        off = self._rng.uniform(size, max(size, float(self.cfg['lateral_jitter'])))
        cy = self.cell.belt.centre_y
        self.spawn_item(cls, cy + off)
        self.spawn_item(cls, cy - off)

    # --- items ----------------------------------------------------------------------------
    def create_item(self, cls: str, pos, mass: float, state: str,
                    size: Optional[float] = None, item_id: Optional[int] = None) -> ItemRecord:
        """Create an item body (the item size unless ``size``) at ``pos`` and record it.

        Its id is the next of this belt's own, or ``item_id`` (an item handed on from upstream).
        """
        pb = self._pb
        colour = (*class_colour(cls, self.cell.item_classes), 1.0)
        if size is None:
            shape = self._item_shape
            if cls not in self._item_visual:
                self._item_visual[cls] = pb.createVisualShape(
                    pybullet.GEOM_BOX, halfExtents=[self.cell.item_size / 2] * 3,
                    rgbaColor=colour)
            visual = self._item_visual[cls]
        else:
            shape = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[size / 2] * 3)
            visual = pb.createVisualShape(pybullet.GEOM_BOX, halfExtents=[size / 2] * 3,
                                          rgbaColor=colour)
        body = pb.createMultiBody(mass, shape, visual, [float(v) for v in pos],
                                  useMaximalCoordinates=True)
        pb.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0)
        if item_id is None:
            item_id = self._next_id
            self._next_id += 1
        rec = ItemRecord(item_id, body, cls, mass, state)
        self.records[rec.id] = rec
        return rec

    def spawn_item(self, cls: Optional[str] = None, y: Optional[float] = None,
                   x: Optional[float] = None) -> int:
        """Put an item on the belt, moving at belt speed; return its id.

        :param cls: item class; default: random (seeded).
        :param y: lateral position (world); default: belt centre + uniform jitter.
        :param x: position along the belt; default: the inlet, ``x_start + inlet_margin``.
        :raises ValueError: unknown class, or a position off the belt.
        """
        belt = self.cell.belt
        classes = self.cell.item_classes
        if cls is None:
            cls = classes[int(self._rng.integers(len(classes)))]
        if cls not in classes:
            raise ValueError(f'unknown item class {cls!r}; the cell sorts {list(classes)}')
        jitter = float(self.cfg['lateral_jitter'])
        y = belt.centre_y + self._rng.uniform(-jitter, jitter) if y is None else float(y)
        x = belt.x_start + float(self.cfg['inlet_margin']) if x is None else float(x)
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f'item position must be finite, got x={x}, y={y}')
        if abs(y - belt.centre_y) > self._half_free + 1e-9:
            raise ValueError(f'y={y:.3f} puts the item off the belt (|y - {belt.centre_y}| '
                             f'<= {self._half_free:.3f})')
        if not belt.x_start <= x < belt.x_end:
            raise ValueError(f'x={x:.3f} is not on the belt [{belt.x_start}, {belt.x_end})')
        return self.place(cls, x, y, 'spawned').id

    def place(self, cls: str, x: float, y: float, kind: str,
              item_id: Optional[int] = None) -> ItemRecord:
        """Put an item on the belt at ``(x, y)``, moving at belt speed; event ``kind``.

        Its id is the next of this belt's own, or ``item_id`` (an item handed on from upstream).
        """
        belt = self.cell.belt
        z = belt.top_z + self.cell.item_size / 2.0
        rec = self.create_item(cls, (x, y, z), self.cell.item_mass, 'belt', item_id=item_id)
        self._set_vel(rec.body, [belt.speed, 0.0, 0.0], [0.0, 0.0, 0.0])
        self.event(kind, rec)
        return rec

    def number_from(self, first_id: int) -> None:
        """Give this belt's own items ids from ``first_id`` on (or later, if taken already)."""
        self._next_id = max(self._next_id, int(first_id))

    def resting(self) -> List[Tuple[ItemRecord, Tuple[float, float, float]]]:
        """Return the items resting on the belt, each with its centre (world, m)."""
        return [(rec, self._get_pose(rec.body)[0]) for rec in self.records.values()
                if rec.state == 'belt']

    def belt_boxes(self) -> list:
        """Return the axis-aligned boxes ``(lo, hi)`` of the items resting on the belt."""
        return [self._pb.getAABB(r.body) for r in self.records.values() if r.state == 'belt']

    def _remove(self, rec: ItemRecord, kind: str, robot: str = '') -> None:
        if rec.constraint is not None:
            self._pb.removeConstraint(rec.constraint)
        self._pb.removeBody(rec.body)
        del self.records[rec.id]
        self.event(kind, rec, robot, rec.cause if kind in ('dropped', 'missed') else '')

    def update(self) -> None:
        """Feed, carry items on the belt, detect missed / sorted / wrong_bin / dropped."""
        now = self._clock()
        self.checked = now
        if self.feed.due(now):
            self._feed()
        self.line.arrive(now)
        belt = self.cell.belt
        carry = [belt.speed, 0.0, 0.0]
        zero = [0.0, 0.0, 0.0]
        rest_speed_sq = float(self.cfg['rest_speed']) ** 2
        for rec in list(self.records.values()):
            if rec.state == 'held':
                continue
            x, y, z = self._get_pose(rec.body)[0]
            if x > belt.x_end and rec.state == 'belt':  # carried off the end (maybe tipping)
                self._remove(rec, self.line.crossed(rec, x, y, now))
                continue
            if on_belt(self.cell, (x, y, z)):
                rec.state = 'belt'
                self._set_vel(rec.body, carry, zero)
                continue
            if rec.state == 'belt' and not rec.cause:  # it left the belt without a grasp
                rec.cause = self._touching(rec)
            rec.state = 'free'
            if z < _LOST_Z:
                self._remove(rec, 'dropped', rec.last_robot)
                continue
            v = self._get_vel(rec.body)[0]
            if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > rest_speed_sq:
                continue
            for b in self.bins:
                if abs(x - b.x) < b.half_x and abs(y - b.y) < b.half_y and z < b.top:
                    self._remove(rec, 'sorted' if b.cls == rec.cls else 'wrong_bin', b.robot)
                    break
            else:
                if z < self.cell.item_size:
                    self._remove(rec, 'dropped', rec.last_robot)

    def _touching(self, rec: ItemRecord) -> str:
        """Name what touches an item now: an arm link, another item, or nothing."""
        others = {r.body: r for r in self.records.values() if r is not rec}
        found = ''
        for c in self._pb.getContactPoints(bodyA=rec.body):
            if c[2] == self._cell_body:
                return f'knocked by {self._link_names.get(c[4], "the cell")}'
            if c[2] in others and not found:
                other = others[c[2]]
                found = f'pushed by item {other.id}' + (
                    f' (held by {other.holder})' if other.holder is not None else '')
        return found or 'left the belt with nothing touching it'

    def items(self) -> List[Item]:
        """Every item in the cell now (positions and velocities read from PyBullet)."""
        out = []
        for rec in self.records.values():
            pos = self._get_pose(rec.body)[0]
            vel = self._get_vel(rec.body)[0]
            out.append(Item(rec.id, rec.cls, np.array(pos), np.array(vel), rec.state))
        return out

    def event(self, kind: str, rec: ItemRecord, robot: str = '', cause: str = '') -> None:
        """Record that ``kind`` happened to the item of ``rec`` now."""
        self._events.append(SimEvent(self._clock(), kind, rec.id, rec.cls, robot, cause))

    def pop_events(self) -> List[SimEvent]:
        """Events since the last call, oldest first (the list is emptied)."""
        events, self._events = self._events, []
        return events
