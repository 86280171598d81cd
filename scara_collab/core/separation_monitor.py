"""The separation monitor's decisions, without ROS: scans in, a speed factor per arm out.

:class:`SeparationMonitor` is fed the safety scanners' ranges (:meth:`~SeparationMonitor.observe`)
and asked for a decision at any time (:meth:`~SeparationMonitor.decide`): per arm the speed
factor ``s`` in [0, 1] its trajectory clock runs at (:mod:`scara_collab.core.scaled_clock`)
and whether it must stop (a protective stop), with the cause as text. It never reads where
the person really is: only the ranges, and the arms' own joint states (to know where the arms
are, and to mute the quills in the scan plane).

The steps (each in its own module):

1. scans -> persons: :mod:`scara_collab.core.scan_tracking` (contour, foreground, muting,
   clusters, tracks); a person is a column of the cluster's radius plus ``body_margin``,
   ``column_height`` tall, grown at the walking speed while it is not seen;
2. persons -> the factor each arm is allowed: :func:`scara_collab.core.ssm.assess_arm`;
3. the factor given: :class:`ScaleGovernor`, per arm.

**Fail closed.** Every arm gets ``s = 0`` and a protective stop, with the reason, while the
contour is not taught, while any scanner's last scan is older than ``stale_after`` (1.5 scan
periods: decided at 100 Hz, the stop comes within two periods of the last scan) or had a
range it could not measure (NaN, ``-inf``, below ``range_min``: REP 117), and for an arm whose
joint state is not finite.

**The factor given** (:class:`ScaleGovernor`). It *falls* to what the separation allows, at
most at the braking rate ``1 / T_s`` (:func:`scara_collab.core.ssm.braking_rate`): lowering
``s`` at that rate slows the joints exactly as the stop that ``S_p`` counts on, so asking
faster would not stop the arm sooner and asking slower would break the assumption. It *rises*
only to what the separation less the hysteresis allows (``hysteresis`` m), only after that has
been above the current factor for ``dwell`` s, and at most at ``resume_rate`` per second: a
person standing at the edge of ``S_p`` does not make the arm chatter. A protective stop ends
by itself: once the separation allows motion again, the factor rises from 0 after the dwell.

This is a simulation of a safety function, not a certified one.
"""
from dataclasses import dataclass, replace
import math
from typing import List, Mapping, NamedTuple, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

from scara_collab.core.collision import arm_capsules, segment_distance
from scara_collab.core.kinematics import fk
from scara_collab.core.model import ArmModel, CellModel
from scara_collab.core.scan_tracking import (
    cell_mute_boxes, clusters, foreground, inside_boxes, near_points, range_faults,
    ScanGeometry, teach_contour, Tracker)
from scara_collab.core.ssm import assess_arm, braking_rate, Person, SsmParams


@dataclass(frozen=True)
class MonitorSettings:
    """The monitor's numbers (``config/people.yaml``, sections ``monitor`` and ``scanner``).

    :ivar ssm: the protective separation's numbers.
    :ivar scan_period: s between two scans of a scanner.
    :ivar stale_after: s without a scan from a scanner before every arm stops.
    :ivar foreground: m a return must fall short of the contour by.
    :ivar teach_scans: scans per scanner taught as the contour.
    :ivar cluster_gap: m between returns of one person.
    :ivar min_points: returns a cluster needs to count at once.
    :ivar body_margin: m added to a cluster's radius.
    :ivar column_height: m, the person's column.
    :ivar mute_margin: m around the belt and the bins.
    :ivar self_filter_radius: m around each arm's quill axis.
    :ivar track_gate: m; :ivar track_hold: s; :ivar velocity_window: s (the tracker's).
    :ivar dwell: s; :ivar resume_rate: 1/s (the governor's).
    """

    ssm: SsmParams
    scan_period: float
    stale_after: float
    foreground: float
    teach_scans: int
    cluster_gap: float
    min_points: int
    body_margin: float
    column_height: float
    mute_margin: float
    self_filter_radius: float
    track_gate: float
    track_hold: float
    velocity_window: float
    dwell: float
    resume_rate: float

    @staticmethod
    def from_config(cfg: dict) -> 'MonitorSettings':
        """Build them from the validated ``people`` config."""
        mon = cfg['monitor']
        keys = ('stale_after', 'foreground', 'cluster_gap', 'body_margin', 'column_height',
                'mute_margin', 'self_filter_radius', 'track_gate', 'track_hold',
                'velocity_window', 'dwell', 'resume_rate')
        return MonitorSettings(
            ssm=SsmParams.from_config(cfg), scan_period=1.0 / float(cfg['scanner']['rate']),
            teach_scans=int(mon['teach_scans']), min_points=int(mon['min_points']),
            **{k: float(mon[k]) for k in keys})


class PersonSeen(NamedTuple):
    """A tracked person as it travels in a status: the column's centre, radius and velocity.

    :ivar id: the track's number; :ivar x, y: m (world); :ivar radius: m; :ivar vx, vy: m/s.
    """

    id: int
    x: float
    y: float
    radius: float
    vx: float
    vy: float

    @staticmethod
    def of(person: Person) -> 'PersonSeen':
        """Return ``person`` (:class:`~scara_collab.core.ssm.Person`) as a record."""
        return PersonSeen(int(person.id), float(person.position[0]), float(person.position[1]),
                          float(person.radius), float(person.velocity[0]),
                          float(person.velocity[1]))


@dataclass(frozen=True)
class ArmDecision:
    """What one arm is told.

    :ivar robot: the arm.
    :ivar scale: the speed factor ``s`` in [0, 1] its trajectory clock runs at.
    :ivar stop: True for a protective stop (brake and hold).
    :ivar cause: why ``s < 1`` or why it stops, else ``''``.
    :ivar separation: the smallest separation from a person, m (``inf`` for none).
    :ivar margin: the smallest ``S - S_p`` at the planned speed, m (``inf`` for none).
    :ivar required: the factor the separation allows now (before the governor).
    """

    robot: str
    scale: float
    stop: bool
    cause: str
    separation: float = math.inf
    margin: float = math.inf
    required: float = 1.0


@dataclass(frozen=True)
class Decision:
    """The monitor's decision at ``time``: one :class:`ArmDecision` per arm, and the persons.

    :ivar fault: why every arm stops regardless of the persons (fail closed), else ``''``.
    """

    time: float
    arms: Tuple[ArmDecision, ...]
    persons: Tuple[Person, ...]
    fault: str = ''

    def arm(self, robot: str) -> ArmDecision:
        """Return the decision of ``robot``."""
        for a in self.arms:
            if a.robot == robot:
                return a
        raise KeyError(f'no arm {robot!r} in the decision')


class ScaleGovernor:
    """The factor one arm is given: falls at the braking rate, rises after a dwell, slowly.

    See the module docstring. It starts at 0: nothing moves before the first good decision,
    which sets the factor at once to what it allows (the cell starts at rest: there is no
    motion to spare a sudden rise, and the bridge's trajectory clocks still rise within the
    joints' limits); from then on it falls and rises as above.

    :param dwell: s the relaxed factor must exceed the current one before it rises.
    :param resume_rate: 1/s, the fastest rise.
    """

    def __init__(self, dwell: float, resume_rate: float):
        """Start at 0, with no time yet."""
        self.dwell, self.resume_rate = dwell, resume_rate
        self.scale = 0.0
        self._time: Optional[float] = None
        self._rising_since: Optional[float] = None
        self._started = False  # the first good decision sets the factor at once

    def update(self, now: float, required: float, relaxed: float, fall_rate: float) -> float:
        """Return the factor at ``now``.

        :param required: what the separation allows now; the factor never exceeds it.
        :param relaxed: what the separation less the hysteresis allows: what a rise may reach.
        :param fall_rate: 1/s, the fastest fall (the braking rate; ``inf`` at rest).
        """
        last = now if self._time is None else min(self._time, now)
        self._time = now
        dt = now - last
        relaxed = min(relaxed, required)
        if not self._started:  # the cell starts at rest: what the first look allows, at once
            self._started = True
            self.scale = relaxed
            return self.scale
        if required < self.scale:
            step = fall_rate * dt if math.isfinite(fall_rate) else math.inf
            self.scale = max(required, self.scale - step) if required > 0.0 else 0.0
            self._rising_since = None
        elif relaxed > self.scale:
            if self._rising_since is None:
                self._rising_since = now
            rise_from = max(last, self._rising_since + self.dwell)
            if now > rise_from:
                self.scale = min(relaxed, self.scale + self.resume_rate * (now - rise_from))
        else:
            self._rising_since = None
        return self.scale

    def halt(self, now: float) -> float:
        """Drop the factor to 0 at once (a fault or a stop) and restart the dwell."""
        self.scale = 0.0
        self._time = now
        self._rising_since = None
        return 0.0


def nearest_person(arm: ArmModel, q: ArrayLike, persons: Sequence[Person]
                   ) -> Optional[Person]:
    """Return the person whose column comes nearest to the arm's capsules (None for none).

    Surface to surface, as :func:`~scara_collab.core.ssm.assess_arm` measures ``S``; for the
    viewers, which draw each arm's ``S_p`` around the person it is nearest to.

    :param arm: the arm; :param q: ``(3,)`` its joints.
    :param persons: the persons, as columns.
    """
    if not persons:
        return None
    start, end, radii = arm_capsules(arm, q)
    pos = np.array([p.position for p in persons], dtype=float).reshape(-1, 2)
    bottom = np.column_stack([pos, np.zeros(len(pos))])
    top = np.column_stack([pos, [p.height for p in persons]])
    axis, _, _ = segment_distance(start[None], end[None], bottom[:, None], top[:, None])
    gap = axis - radii[None, :] - np.array([p.radius for p in persons])[:, None]
    return persons[int(np.argmin(gap.min(axis=1)))]


class SeparationMonitor:
    """Speed and separation monitoring of the cell's arms from safety laser scans.

    :param cell: the cell model (the arms, the belt and the bins).
    :param settings: the monitor's numbers.
    :param scanners: the scanners, in the order their scans are given.

    Example: the empty cell taught and scanned; the first look allows full speed at once (the
    cell starts at rest), a silent scanner stops it::

        >>> from scara_collab.core.config import load_config
        >>> from scara_collab.core.model import load_cell
        >>> from scara_collab.core.scan_tracking import scanners_from_config
        >>> cfg = load_config('people')
        >>> cell = load_cell()
        >>> scanners = scanners_from_config(cfg)
        >>> monitor = SeparationMonitor(cell, MonitorSettings.from_config(cfg), scanners)
        >>> empty = [np.full(s.count, np.inf) for s in scanners]
        >>> monitor.teach([[r] for r in empty])
        >>> monitor.observe(0.0, empty, {})
        >>> rest = {a.name: (np.zeros(3), np.zeros(3)) for a in cell.arms}
        >>> monitor.decide(0.0, rest).arm('scara_left').scale
        1.0
        >>> monitor.observe(0.5, empty, {})
        >>> monitor.decide(0.6, rest).arm('scara_left').scale
        0.0
        >>> monitor.decide(0.6, rest).arm('scara_left').cause
        'scanner_a: no scan for 0.100 s'
    """

    def __init__(self, cell: CellModel, settings: MonitorSettings,
                 scanners: Sequence[ScanGeometry]):
        """Set up the tracker and one governor per arm; nothing is taught yet."""
        self.cell, self.settings, self.scanners = cell, settings, tuple(scanners)
        self.contours: Optional[List[np.ndarray]] = None
        self.tracker = Tracker(settings.track_gate, settings.track_hold,
                               settings.velocity_window, settings.min_points)
        self.governors = {a.name: ScaleGovernor(settings.dwell, settings.resume_rate)
                          for a in cell.arms}
        self._mute = cell_mute_boxes(cell, settings.mute_margin)
        self._seen: List[Optional[float]] = [None] * len(self.scanners)
        self._faults: List[str] = [''] * len(self.scanners)
        self.points = np.zeros((0, 2))  # the last foreground points (for viewers and tests)

    @property
    def seen(self) -> Tuple[Optional[float], ...]:
        """Per scanner the stamp of its last scan observed, s (None: none yet)."""
        return tuple(self._seen)

    @property
    def taught(self) -> bool:
        """True once every scanner has its contour."""
        return self.contours is not None

    def teach(self, scans: Sequence[ArrayLike]) -> None:
        """Teach the empty cell's contour: per scanner ``(K, N)`` ranges (:func:`teach_contour`).

        :raises ValueError: for the wrong number of scanners or of rays.
        """
        if len(scans) != len(self.scanners):
            raise ValueError(f'teach needs scans of {len(self.scanners)} scanners, '
                             f'got {len(scans)}')
        contours = []
        for geometry, k_scans in zip(self.scanners, scans):
            k_scans = np.asarray(k_scans, dtype=float).reshape(-1, geometry.count)
            contours.append(teach_contour(k_scans, geometry.range_max))
        self.contours = contours

    def observe(self, stamp: float, scans: Sequence[Optional[ArrayLike]],
                arm_positions: Mapping[str, ArrayLike]) -> None:
        """Take the scans taken at ``stamp`` (None: that scanner sent none).

        :param stamp: sim time of the scans, s.
        :param scans: per scanner its ranges ``(N,)``, or None.
        :param arm_positions: ``{robot: (3,) joints}`` at ``stamp``: each arm's quill axis is
            muted (an arm left out is not muted).
        """
        if len(scans) != len(self.scanners):
            raise ValueError(f'observe needs {len(self.scanners)} scans, got {len(scans)}')
        quills = None  # where the quills cross the plane: looked up once a return needs it
        found = []
        for i, (geometry, ranges) in enumerate(zip(self.scanners, scans)):
            if ranges is None:
                continue
            ranges = np.asarray(ranges, dtype=float)
            bad = range_faults(ranges, geometry)
            self._seen[i] = stamp
            self._faults[i] = f'{geometry.name}: {bad} rays measured nothing usable' if bad else ''
            if bad or self.contours is None:
                continue
            mask = foreground(ranges, self.contours[i], self.settings.foreground,
                              geometry.range_max)
            if not mask.any():  # the empty cell: nothing to sort out
                continue
            if quills is None:
                quills = np.array([fk(self.cell.arm(r), q)[:2] for r, q in arm_positions.items()
                                   if np.all(np.isfinite(q))]).reshape(-1, 2)
            pts = geometry.points(ranges, mask)
            keep = ~(inside_boxes(pts, self._mute)
                     | near_points(pts, quills, self.settings.self_filter_radius))
            found.append(pts[keep])
        self.points = np.concatenate(found) if found else np.zeros((0, 2))
        self.tracker.update(stamp, clusters(self.points, self.settings.cluster_gap))

    def persons(self, now: float) -> Tuple[Person, ...]:
        """Return the tracked persons as columns at ``now`` (grown while not seen)."""
        st = self.settings
        out = []
        for track in self.tracker.tracks:
            unseen = max(0.0, now - track.seen - st.scan_period)
            out.append(Person(track.position, track.velocity(st.velocity_window),
                              track.radius + st.body_margin + st.ssm.walking_speed * unseen,
                              st.column_height, track.id))
        return tuple(out)

    def fault(self, now: float) -> str:
        """Return why every arm must stop regardless of the persons at ``now``, else ``''``."""
        if self.contours is None:
            return "the empty cell's contour is not taught"
        for geometry, seen, fault in zip(self.scanners, self._seen, self._faults):
            if seen is None:
                return f'{geometry.name}: no scan yet'
            if now - seen > self.settings.stale_after:
                return f'{geometry.name}: no scan for {now - seen:.3f} s'
            if fault:
                return fault
        return ''

    def decide(self, now: float, planned: Mapping[str, Tuple[ArrayLike, ...]]) -> Decision:
        """Return the decision at ``now``.

        :param now: sim time, s.
        :param planned: ``{robot: (q, qd)}`` or ``{robot: (q, qd, measured)}``: each arm's
            joints and its *planned* joint velocities, unscaled (the bridge's
            ``Servo.planned_ahead``: the fastest the trajectory goes within a reaction time and
            a scan period; :meth:`ScaledClock.planned_velocity
            <scara_collab.core.scaled_clock.ScaledClock.planned_velocity>` at an instant), the
            factor scales them; with ``measured``, the arm is weighed at each and the lower
            factor taken (an arm braking from a hold has nothing planned but still moves; the
            speed towards a person is directed, so neither bounds the other). An arm left out
            is stopped.
        :return: the :class:`Decision`.
        """
        fault = self.fault(now)
        persons = () if fault else self.persons(now)
        arms = []
        for arm in self.cell.arms:
            gov = self.governors[arm.name]
            state = planned.get(arm.name)
            vectors = [] if state is None else [np.asarray(v, dtype=float) for v in state]
            why = fault
            if not why and (len(vectors) < 2 or any(
                    v.shape != (3,) or not np.all(np.isfinite(v)) for v in vectors)):
                why = f'{arm.name}: no finite joint state'
            if why:
                arms.append(ArmDecision(arm.name, gov.halt(now), True, why, required=0.0))
                continue
            q, qd = vectors[0], vectors[1]
            each = [assess_arm(arm, q, v, persons, self.settings.ssm) for v in vectors[1:]]
            assessed = replace(min(each, key=lambda a: a.scale),
                               relaxed=min(a.relaxed for a in each),
                               stop=any(a.stop for a in each))
            s = gov.update(now, assessed.scale, assessed.relaxed, braking_rate(arm, qd))
            cause = assessed.cause
            if s < assessed.scale and not cause:
                cause = f'{arm.name}: resuming'
            arms.append(ArmDecision(arm.name, s, assessed.stop, cause, assessed.separation,
                                    assessed.margin, assessed.scale))
        return Decision(now, tuple(arms), persons, fault)
