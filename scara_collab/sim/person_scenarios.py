"""Where the simulated person goes and what it does: scenarios of waypoints, compiled to a path.

A :class:`Scenario` is a list of *visits*: the person appears at its first waypoint at the
visit's start time, walks from waypoint to waypoint at the visit's speed, stays ``dwell``
seconds where a waypoint says so (turned to face a point; *working* there if it says so:
leaning over and reaching out again and again), and vanishes at its last waypoint. Built in
(:data:`BUILTIN`, from the cell model and ``config/people.yaml``):

- ``pass-by``: walks across the floor along its inlet edge, outside every arm's protective
  separation: it must cost nothing;
- ``inlet``: walks to the belt's inlet end and works there 60 s, leaning over the belt, then
  leaves;
- ``middle``: enters between a left bin and the left pillar to the belt's middle, works there
  20 s, then leaves the same way;
- ``random``: seeded arrivals (exponential intervals), entry points on the floor's edges,
  goals at the belt, at a bin or across the floor, dwell times and speeds;
- ``nobody``: no visit: the safety scanners and the separation monitor run and nobody comes
  (what the safety function costs, and whether it slows an arm for nothing).

A YAML file gives a scenario of one's own (:func:`load_scenario`)::

    visits:
      - start: 5.0            # s
        speed: 1.2            # m/s walking
        waypoints:
          - [-6.0, -3.0]                                  # appears here
          - {x: -0.95, y: 0.0, dwell: 30.0, face: [0.0, 0.0], work: true}
          - [-6.0, 3.0]                                   # leaves here

:class:`PersonPath` compiles a scenario into keyframes (time, position, heading, lean, reach,
gait phase) between which every quantity is linear in time: walking at constant speed,
turning at ``turn_rate``, the hand swinging out at ``reach_speed``. The body
(:mod:`scara_collab.sim.person`) is posed from them.
"""
from dataclasses import dataclass
import math
from pathlib import Path
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike
import yaml

from scara_collab.core.config import ConfigError
from scara_collab.core.model import CellModel

BUILTIN = ('pass-by', 'inlet', 'middle', 'random', 'nobody')
#: the keyframe columns of :class:`PersonPath`
COLUMNS = ('x', 'y', 'heading', 'lean', 'reach', 'phase')
#: s the torso takes to lean over (or straighten), an assumption
LEAN_TIME = 0.5
#: m: where a person stands before the belt's edge or a bin (the legs' centre)
STAND_OFF = 0.4
#: m/s: speeds above this are not walking (ISO 13855 covers walking, not running)
MAX_WALKING = 1.6


@dataclass(frozen=True)
class Waypoint:
    """A place on the person's way.

    :ivar x, y: on the floor, world, m.
    :ivar dwell: s it stays there.
    :ivar face: ``(x, y)`` it turns to while it stays, or None (keeps its heading).
    :ivar work: True: it leans over and reaches out towards ``face`` while it stays.
    """

    x: float
    y: float
    dwell: float = 0.0
    face: Optional[Tuple[float, float]] = None
    work: bool = False


@dataclass(frozen=True)
class Visit:
    """One appearance: from its first waypoint (at ``start``, s) to its last, at ``speed``."""

    start: float
    speed: float
    waypoints: Tuple[Waypoint, ...]


@dataclass(frozen=True)
class Scenario:
    """A named list of visits, in time order."""

    name: str
    visits: Tuple[Visit, ...]


@dataclass(frozen=True)
class Motion:
    """The person's motion limits and work cycle (``config/people.yaml``, ``person``).

    :ivar reach_speed: m/s of the hand; :ivar turn_rate: rad/s.
    :ivar reach_pitch: rad below horizontal the hand reaches to; :ivar lean: rad.
    :ivar hold: s the hand stays out; :ivar rest: s between reaches.
    :ivar arm_length: m, shoulder to the hand capsule's end (the hand's swing radius).
    :ivar step_length: m per step.
    """

    reach_speed: float
    turn_rate: float
    reach_pitch: float
    lean: float
    hold: float
    rest: float
    arm_length: float
    step_length: float

    @staticmethod
    def from_config(cfg: dict) -> 'Motion':
        """Build it from the validated ``people`` config."""
        p = cfg['person']
        body = p['body']
        return Motion(float(p['reach_speed']), float(p['turn_rate']),
                      float(p['work']['reach_pitch']), float(p['work']['lean']),
                      float(p['work']['hold']), float(p['work']['rest']),
                      float(body['reach'] - body['arm_radius']), float(body['step_length']))

    @property
    def reach_time(self) -> float:
        """Return the seconds the hand takes from hanging to reaching out (at ``reach_speed``)."""
        return self.arm_length * (math.pi / 2.0 - self.reach_pitch) / self.reach_speed


def _waypoint(item, where: str) -> Waypoint:
    if isinstance(item, (list, tuple)) and len(item) == 2:
        item = {'x': item[0], 'y': item[1]}
    if not isinstance(item, dict) or 'x' not in item or 'y' not in item:
        raise ConfigError(f'{where}: a waypoint is [x, y] or {{x: , y: , dwell: , face: , '
                          f'work: }}, got {item!r}')
    unknown = set(item) - {'x', 'y', 'dwell', 'face', 'work'}
    if unknown:
        raise ConfigError(f'{where}: unknown waypoint keys {sorted(unknown)}')
    try:
        x, y, dwell = float(item['x']), float(item['y']), float(item.get('dwell', 0.0))
        face = item.get('face')
        face = None if face is None else (float(face[0]), float(face[1]))
    except (TypeError, ValueError, IndexError):
        raise ConfigError(f'{where}: waypoint values must be numbers, got {item!r}') from None
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(dwell) and dwell >= 0):
        raise ConfigError(f'{where}: waypoint needs finite x, y and dwell >= 0, got {item!r}')
    work = bool(item.get('work', False))
    if work and face is None:
        raise ConfigError(f'{where}: a work waypoint needs a face point to work towards')
    return Waypoint(x, y, dwell, face, work)


def scenario_from_dict(doc, name: str = 'file', earliest: float = 0.0) -> Scenario:
    """Build and check a scenario from ``{visits: [{start, speed, waypoints}, ...]}``.

    :param earliest: s before which no visit may start (the empty cell is taught first).
    :raises ConfigError: naming what is wrong.
    """
    if not isinstance(doc, dict) or not isinstance(doc.get('visits'), list) or not doc['visits']:
        raise ConfigError(f'{name}: a scenario is {{visits: [...]}} with at least one visit')
    visits = []
    for i, v in enumerate(doc['visits']):
        where = f'{name}: visit {i}'
        if not isinstance(v, dict) or not isinstance(v.get('waypoints'), list):
            raise ConfigError(f'{where}: needs start, speed and waypoints')
        try:
            start, speed = float(v.get('start', 0.0)), float(v.get('speed', 1.2))
        except (TypeError, ValueError):
            raise ConfigError(f'{where}: start and speed must be numbers') from None
        if not (math.isfinite(start) and start >= earliest):
            raise ConfigError(f'{where}: start must be >= {earliest} s (the empty cell is '
                              f'taught before), got {start}')
        if not 0.0 < speed <= MAX_WALKING:
            raise ConfigError(f'{where}: speed must be in (0, {MAX_WALKING}] m/s, got {speed}')
        points = tuple(_waypoint(w, where) for w in v['waypoints'])
        if not points:
            raise ConfigError(f'{where}: needs at least one waypoint')
        visits.append(Visit(start, speed, points))
    visits.sort(key=lambda v: v.start)
    return Scenario(name, tuple(visits))


def load_scenario(path: Union[str, Path], earliest: float = 0.0) -> Scenario:
    """Read a scenario from a YAML file (module docstring).

    :raises ConfigError: for a missing file, bad YAML or a bad scenario.
    """
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f'{path}: no such scenario file') from None
    except yaml.YAMLError as exc:
        raise ConfigError(f'{path}: not valid YAML: {exc}') from None
    return scenario_from_dict(doc, path.stem, earliest)


# --- the built-in scenarios -----------------------------------------------------------------
def _belt_edge(cell: CellModel, x: float, side: float) -> Tuple[Waypoint, Tuple[float, float]]:
    """Return where to stand at the belt's edge at ``x`` on ``side`` (-1 / +1), and the face."""
    belt = cell.belt
    y = belt.centre_y + side * (belt.width / 2.0 + STAND_OFF)
    return Waypoint(x, y), (x, belt.centre_y)


def pass_by(cell: CellModel, cfg: dict) -> Scenario:
    """Walk across the floor along its inlet edge, half a metre inside it."""
    x0, _, y0, y1 = cfg['person']['floor']
    speed = float(cfg['person']['walking_speed'])
    x = x0 + 0.5
    start = float(cfg['person']['earliest']) + 1.0
    return Scenario('pass-by', (Visit(start, speed, (Waypoint(x, y0), Waypoint(x, y1))),))


def inlet(cell: CellModel, cfg: dict, work: float = 60.0) -> Scenario:
    """Walk to the belt's inlet end, work there ``work`` s leaning over the belt, leave."""
    x0, _, y0, y1 = cfg['person']['floor']
    belt = cell.belt
    stand = Waypoint(belt.x_start - STAND_OFF - 0.05, belt.centre_y, work,
                     (belt.x_start + 0.3, belt.centre_y), True)
    speed = float(cfg['person']['walking_speed'])
    start = float(cfg['person']['earliest']) + 1.0
    return Scenario('inlet', (Visit(start, speed, (
        Waypoint(x0, y0 / 2.0), stand, Waypoint(x0, y1 / 2.0))),))


def middle(cell: CellModel, cfg: dict, work: float = 20.0) -> Scenario:
    """Enter between the leader's first bin and its pillar, work at the belt's middle, leave."""
    _, _, y0, _ = cfg['person']['floor']
    belt = cell.belt
    arm = cell.leader
    base = arm.base[:2, 3]
    side = -1.0 if base[1] < belt.centre_y else 1.0
    bin_x = min(float(c[0]) for (robot, _), c in cell.bins.items() if robot == arm.name)
    half_bin = cell.config['bins']['size'][0] / 2.0
    lane = 0.5 * (bin_x + half_bin + base[0] - cell.config['arm']['base_radius'])
    mid = 0.5 * (belt.x_start + belt.x_end)
    edge, face = _belt_edge(cell, mid, side)
    approach = Waypoint(lane, edge.y + side * 0.3)
    here = Waypoint(edge.x, edge.y, work, face, True)
    speed = float(cfg['person']['walking_speed'])
    start = float(cfg['person']['earliest']) + 1.0
    out = Waypoint(lane, side * abs(y0))
    return Scenario('middle', (Visit(start, speed, (out, approach, here, approach, out)),))


def _free_lanes(cell: CellModel, side: float, clear: float) -> List[Tuple[float, float]]:
    """Return the x intervals along the belt on ``side`` where no bin or pillar is in the way.

    :param clear: m a walking person's centre keeps from a bin's or a pillar's edge.
    """
    belt = cell.belt
    blocked = []
    half_bin = cell.config['bins']['size'][0] / 2.0 + clear
    for (robot, _), c in cell.bins.items():
        if (c[1] - belt.centre_y) * side > 0:
            blocked.append((c[0] - half_bin, c[0] + half_bin))
    r = cell.config['arm']['base_radius'] + clear
    for arm in cell.arms:
        if (arm.base[1, 3] - belt.centre_y) * side > 0:
            blocked.append((arm.base[0, 3] - r, arm.base[0, 3] + r))
    lanes, x = [], belt.x_start
    for lo, hi in sorted(blocked):
        if lo > x:
            lanes.append((x, lo))
        x = max(x, hi)
    if x < belt.x_end:
        lanes.append((x, belt.x_end))
    return lanes


def random_scenario(cell: CellModel, cfg: dict, seed: int) -> Scenario:
    """Seeded arrivals until ``random.horizon``: entry, goal, dwell, exit (module docstring).

    Each visit keeps to one side of the belt: it enters on that side's edge (or the inlet or
    outlet edge beyond the bins), walks to a staging point beyond the bins and pillars, then
    straight to its goal along a free lane (at the belt's edge or at a bin, working there) or
    on across the floor, and leaves by another edge point on the same side.
    """
    p = cfg['person']
    rnd = p['random']
    x0, x1, y0, y1 = (float(v) for v in p['floor'])
    rng = np.random.default_rng(seed)
    belt = cell.belt
    size = cell.config['bins']['size']
    body = p['body']
    clear = body['stance'] + body['leg_radius'] + body['step_amplitude'] + 0.1
    beyond = max(abs(float(c[1]) - belt.centre_y) + size[1] / 2.0 for c in cell.bins.values())
    beyond += STAND_OFF + 0.5
    visits = []
    t = float(p['earliest']) + rng.exponential(rnd['mean_interval'])
    while t < rnd['horizon']:
        side = float(rng.choice([-1.0, 1.0]))
        edge_y = y0 if side < 0 else y1
        stage_y = belt.centre_y + side * beyond

        def edge_point():
            if rng.random() < 0.6:  # the side's long edge
                return Waypoint(float(rng.uniform(x0 + 0.5, x1 - 0.5)), edge_y - side * 0.3)
            x = x0 if rng.random() < 0.5 else x1  # an end edge, beyond the bins
            lo, hi = sorted((stage_y, edge_y - side * 0.3))
            return Waypoint(x + (0.3 if x == x0 else -0.3), float(rng.uniform(lo, hi)))

        speed = float(rng.uniform(*rnd['speed']))
        dwell = float(rng.uniform(*rnd['dwell']))
        goal = rng.choice(['belt', 'bin', 'cross'], p=[0.5, 0.25, 0.25])
        entry, leave = edge_point(), edge_point()
        if goal == 'cross':
            points = (entry, Waypoint(float(rng.uniform(x0 + 0.5, x1 - 0.5)), stage_y), leave)
        else:
            if goal == 'belt':
                lanes = _free_lanes(cell, side, clear)
                lo, hi = lanes[int(rng.integers(len(lanes)))]
                x = float(rng.uniform(lo, hi))
                stand, face = _belt_edge(cell, x, side)
            else:
                bins = [c for c in cell.bins.values() if (c[1] - belt.centre_y) * side > 0]
                c = bins[int(rng.integers(len(bins)))]
                x = float(c[0])
                stand = Waypoint(x, float(c[1]) + side * (size[1] / 2.0 + STAND_OFF))
                face = (x, float(c[1]))
            stage = Waypoint(x, stage_y)
            here = Waypoint(stand.x, stand.y, dwell, face, True)
            points = (entry, stage, here, stage, leave)
        visits.append(Visit(t, speed, points))
        t += _duration(points, speed) + rng.exponential(rnd['mean_interval'])
    return Scenario(f'random (seed {seed})', tuple(visits))


def _duration(points: Sequence[Waypoint], speed: float) -> float:
    """Return a visit's walking and dwelling time, s (turning left out)."""
    walk = sum(math.hypot(b.x - a.x, b.y - a.y) for a, b in zip(points, points[1:]))
    return walk / speed + sum(w.dwell for w in points)


def scenario(spec: str, cell: CellModel, cfg: dict, seed: Optional[int] = None
             ) -> Optional[Scenario]:
    """Return the scenario ``spec`` names: ``none``, a built-in name or a YAML file's path.

    :param seed: the random scenario's seed; default ``person.seed``.
    :raises ConfigError: for an unknown name or a bad file.
    """
    if spec in ('', 'none'):
        return None
    if spec == 'pass-by':
        return pass_by(cell, cfg)
    if spec == 'inlet':
        return inlet(cell, cfg)
    if spec == 'middle':
        return middle(cell, cfg)
    if spec == 'random':
        return random_scenario(cell, cfg, int(cfg['person']['seed'] if seed is None else seed))
    if spec == 'nobody':
        return Scenario('nobody', ())
    if spec.endswith(('.yaml', '.yml')) or Path(spec).exists():
        return load_scenario(spec, float(cfg['person']['earliest']))
    raise ConfigError(f'unknown person scenario {spec!r}; expected none, one of {BUILTIN} '
                      'or a YAML file')


class PersonPath:
    """A scenario compiled to keyframes, linear in time between them (module docstring).

    :param scenario: the scenario.
    :param motion: the person's limits and work cycle.
    """

    def __init__(self, scenario: Scenario, motion: Motion):
        """Compile every visit into keyframes."""
        self.scenario, self.motion = scenario, motion
        rows: List[List[float]] = []
        self.visits: List[Tuple[float, float]] = []  # (appears, vanishes)
        for visit in scenario.visits:
            start = len(rows)
            self._visit(visit, rows)
            self.visits.append((rows[start][0], rows[-1][0]))
        table = np.array(rows, dtype=float).reshape(-1, 1 + len(COLUMNS))
        self.times = table[:, 0]
        self.frames = table[:, 1:]
        self._spans = np.array(self.visits, dtype=float).reshape(-1, 2)
        self._span_list = [tuple(v) for v in self._spans.tolist()]

    # --- compiling ---------------------------------------------------------------------------
    def _visit(self, visit: Visit, rows: List[List[float]]) -> None:
        m = self.motion
        pts = visit.waypoints
        first = pts[0]
        heading = (math.atan2(pts[1].y - first.y, pts[1].x - first.x) if len(pts) > 1
                   else 0.0)
        state = {'t': visit.start, 'x': first.x, 'y': first.y, 'heading': heading,
                 'lean': 0.0, 'reach': 0.0, 'phase': 0.0}

        def emit(dt=0.0, **change):
            state['t'] += dt
            state.update(change)
            rows.append([state['t']] + [state[c] for c in COLUMNS])

        def turn_to(angle):
            diff = (angle - state['heading'] + math.pi) % (2.0 * math.pi) - math.pi
            if abs(diff) > 1e-9:
                emit(abs(diff) / m.turn_rate, heading=state['heading'] + diff)

        emit()
        for here, nxt in zip(pts, list(pts[1:]) + [None]):
            if here.face is not None and here.dwell > 0.0:
                turn_to(math.atan2(here.face[1] - here.y, here.face[0] - here.x))
            if here.work and here.dwell > 0.0:
                self._work(here.dwell, emit)
            elif here.dwell > 0.0:
                emit(here.dwell)
            if nxt is None:
                break
            dist = math.hypot(nxt.x - here.x, nxt.y - here.y)
            if dist < 1e-9:
                continue
            turn_to(math.atan2(nxt.y - here.y, nxt.x - here.x))
            steps = max(1, round(dist / m.step_length))
            emit(dist / visit.speed, x=nxt.x, y=nxt.y, phase=state['phase'] + steps * math.pi)

    def _work(self, dwell: float, emit) -> None:
        """Lean in, reach out and back again while time is left, straighten up."""
        m = self.motion
        lean = min(LEAN_TIME, dwell / 4.0)
        emit(lean, lean=m.lean)
        left = dwell - 2.0 * lean
        cycle = 2.0 * m.reach_time + m.hold
        while left >= cycle:
            emit(m.reach_time, reach=1.0)
            emit(m.hold)
            emit(m.reach_time, reach=0.0)
            left -= cycle
            rest = min(m.rest, left)
            emit(rest)
            left -= rest
        if left > 0.0:
            emit(left)
        emit(lean, lean=0.0)

    # --- evaluating --------------------------------------------------------------------------
    @property
    def end(self) -> float:
        """Return when the last visit ends, s (``-inf`` for an empty scenario)."""
        return float(self.times[-1]) if len(self.times) else -math.inf

    def present(self, t: ArrayLike) -> np.ndarray:
        """Return where the person is in the cell at time(s) ``t`` (bool, the shape of ``t``)."""
        t = np.asarray(t, dtype=float)
        inside = (t[..., None] >= self._spans[:, 0]) & (t[..., None] <= self._spans[:, 1])
        return inside.any(axis=-1)

    def is_present(self, t: float) -> bool:
        """Return :meth:`present` at one time ``t``, in plain floats (every step of the bridge)."""
        return any(start <= t <= end for start, end in self._span_list)

    def state(self, t: ArrayLike) -> np.ndarray:
        """Return the keyframe columns (:data:`COLUMNS`) at time(s) ``t``: ``(..., 6)``.

        Interpolated linearly; outside a visit the values are those of the nearest keyframe
        (use :meth:`present`).
        """
        t = np.asarray(t, dtype=float)
        if not len(self.times):
            return np.zeros(t.shape + (len(COLUMNS),))
        return np.stack([np.interp(t, self.times, self.frames[:, k])
                         for k in range(len(COLUMNS))], axis=-1)
