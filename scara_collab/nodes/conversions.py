"""Message <-> numpy conversions, in one place so no node repeats them.

Also the node clock in seconds (:func:`now`). The statuses the nodes exchange
(DiagnosticStatus key-values) are :mod:`scara_collab.nodes.protocol`'s, not this module's.
"""
import array
import math
from typing import Dict, List, Optional, Sequence, Tuple, Union

from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import (Point, PointStamped, Pose, PoseArray, PoseStamped,
                               TransformStamped)
from nav_msgs.msg import Path
import numpy as np
from sensor_msgs.msg import JointState, LaserScan
from std_msgs.msg import ColorRGBA, Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from scara_collab.core import moves
from scara_collab.core.arm_planner import HoldArm, SendMove
from scara_collab.core.frames import quaternion
from scara_collab.core.palette import class_colour


class MessageError(ValueError):
    """A message was refused; the text says why."""


def to_sec(stamp) -> float:
    """``builtin_interfaces/Time`` or ``Duration`` -> seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def to_time(seconds: float) -> Time:
    """Seconds -> ``builtin_interfaces/Time`` (rounded to the nanosecond)."""
    ns = int(round(seconds * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def request_id(stamp) -> int:
    """``builtin_interfaces/Time`` -> a move request's id: the stamp in integer nanoseconds.

    (:func:`scara_collab.core.moves.request_id`; exact, unlike :func:`to_sec`.)
    """
    return moves.request_id(stamp.sec, stamp.nanosec)


def time_from_ns(ns: int) -> Time:
    """Integer nanoseconds -> ``builtin_interfaces/Time`` (exact)."""
    ns = int(ns)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def to_duration(seconds: float) -> Duration:
    """Seconds -> ``builtin_interfaces/Duration``."""
    ns = int(round(seconds * 1e9))
    return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def joint_state(stamp: float, names: Sequence[str], position, velocity, effort) -> JointState:
    """Build a ``sensor_msgs/JointState``."""
    msg = JointState()
    msg.header.stamp = to_time(stamp)
    msg.name = list(names)
    msg.position = [float(v) for v in position]
    msg.velocity = [float(v) for v in velocity]
    msg.effort = [float(v) for v in effort]
    return msg


def joint_velocities(stamp: float, names: Sequence[str], velocity) -> JointState:
    """Build a ``sensor_msgs/JointState`` of velocities alone (no positions, no efforts)."""
    msg = JointState()
    msg.header.stamp = to_time(stamp)
    msg.name = list(names)
    msg.velocity = [float(v) for v in velocity]
    return msg


def velocity_arrays(msg: JointState, names: Sequence[str]) -> np.ndarray:
    """Return the velocities of ``names`` from a ``JointState`` of velocities (any order).

    :raises MessageError: a name is missing, the names and velocities differ in length, or a
        velocity is not finite.
    """
    if len(msg.velocity) != len(msg.name):
        raise MessageError('velocity and name lengths differ')
    given = dict(zip(msg.name, msg.velocity))
    missing = [n for n in names if n not in given]
    if missing:
        raise MessageError(f'lacks {missing}')
    out = np.array([given[n] for n in names], dtype=float)
    if not np.all(np.isfinite(out)):
        raise MessageError(f'a non-finite velocity of {list(names)}')
    return out


def joint_state_arrays(msg: JointState, names: Sequence[str]) -> Tuple[np.ndarray, np.ndarray]:
    """Positions and velocities of ``names`` from a ``JointState`` (any order).

    :raises MessageError: a name is missing, the arrays are inconsistent, or a value is not
        finite (a NaN state is refused at the door, never planned from or measured).
    """
    have = msg.name
    missing = [n for n in names if n not in have]
    if missing:
        raise MessageError(f'joint_states lacks {missing}')
    if len(msg.position) != len(have):
        raise MessageError('joint_states: position and name lengths differ')
    # plain floats: every node takes every state (100 Hz), a few joints at a time, and numpy's
    # per-call overhead would be most of this function's cost
    if len(set(have)) < len(have):  # a name given twice: its last value, as a dict has it
        last = {n: i for i, n in enumerate(have)}
        idx = [last[n] for n in names]
    else:
        idx = [have.index(n) for n in names]
    position, velocity = msg.position, msg.velocity
    pos = [position[i] for i in idx]
    vel = [velocity[i] for i in idx] if len(velocity) == len(have) else [0.0] * len(idx)
    for v in pos + vel:
        if not math.isfinite(v):
            raise MessageError(f'joint_states: non-finite position or velocity of {list(names)}')
    return np.array(pos), np.array(vel)


#: rad or m: how far a scan's angles and limits may be from its scanner's (float32 fields)
SCAN_TOLERANCE = 1e-4


def scan_ranges(msg: LaserScan, geometry) -> np.ndarray:
    """Return a ``LaserScan``'s ranges ``(N,)`` as floats, after checking it is ``geometry``'s.

    NaN, ``inf`` and short ranges are kept as they are: what they mean is the monitor's
    (:func:`scara_collab.core.scan_tracking.range_faults`).

    :param geometry: the scanner it claims to come from
        (:class:`~scara_collab.core.scan_tracking.ScanGeometry`).
    :raises MessageError: another number of rays, other angles or other range limits.
    """
    if len(msg.ranges) != geometry.count:
        raise MessageError(f'{geometry.name}: {len(msg.ranges)} rays, expected '
                           f'{geometry.count}')
    for key, want in (('angle_min', geometry.angle_min),
                      ('angle_increment', geometry.angle_increment),
                      ('range_min', geometry.range_min), ('range_max', geometry.range_max)):
        got = float(getattr(msg, key))
        if not abs(got - want) <= SCAN_TOLERANCE:
            raise MessageError(f'{geometry.name}: {key} {got:.6g}, expected {want:.6g}')
    return np.asarray(msg.ranges, dtype=float)


#: s: a joint state stamped further than this from the sim clock is refused (the bridge
#: stamps its states with the step it publishes on /clock; a stamp elsewhere is not its)
STAMP_TOLERANCE = 1.0


def now(node) -> float:
    """Return the time of ``node``'s clock in s (sim time on sim time: 0.0 before ``/clock``)."""
    return node.get_clock().now().nanoseconds * 1e-9


def sim_now(node) -> Optional[float]:
    """Return the node's sim time in s, 0.0 before the first ``/clock``; None off sim time."""
    clock = node.get_clock()
    if not getattr(clock, 'ros_time_is_active', False):
        return None
    return clock.now().nanoseconds * 1e-9


class StampGate:
    """Refuse joint states whose stamps cannot be the simulator's.

    A state is refused when its stamp is not finite, older than the last one let through
    (out of order), or further than ``tolerance`` from the sim clock (before the first
    ``/clock``: later than ``tolerance``). One wall-clock-stamped state would otherwise end a
    run or poison every later comparison. With no sim clock (``clock`` None) only order and
    finiteness are checked.
    """

    def __init__(self, tolerance: float = STAMP_TOLERANCE):
        """Let the first finite stamp through; ``tolerance`` is in seconds."""
        self.tolerance = float(tolerance)
        self.last: Optional[float] = None
        self.refused = 0

    def check(self, stamp: float, clock: Optional[float]) -> Optional[str]:
        """Return why a state stamped ``stamp`` (s) is refused, or None and let it through."""
        why = None
        if not math.isfinite(stamp):
            why = f'non-finite stamp {stamp}'
        elif clock is not None and clock <= 0.0 and stamp > self.tolerance:
            why = f'stamp t={stamp:.3f} s before any /clock was heard'
        elif clock is not None and clock > 0.0 and abs(stamp - clock) > self.tolerance:
            why = (f'stamp t={stamp:.3f} s is {stamp - clock:+.3f} s from the sim clock '
                   f'(t={clock:.3f} s)')
        elif self.last is not None and stamp < self.last:
            why = f'stamp t={stamp:.3f} s is older than the last state (t={self.last:.3f} s)'
        if why is None:
            self.last = stamp
        else:
            self.refused += 1
        return why


def admit_state(node, gate: StampGate, msg: JointState) -> bool:
    """Return True if ``msg``'s stamp passes ``gate`` on ``node``'s sim clock.

    A refused state is named in a throttled warning and must be ignored by the caller.
    """
    why = gate.check(to_sec(msg.header.stamp), sim_now(node))
    if why is None:
        return True
    log = node.get_logger()  # one throttled call site per kind: one kind never hides another
    if 'before any /clock' in why:
        log.info(f'ignoring joint_states: {why}', throttle_duration_sec=5.0)
    elif 'from the sim clock' in why:
        log.warning(f'ignoring joint_states: {why}', throttle_duration_sec=5.0)
    else:
        log.warning(f'ignoring joint_states: {why}', throttle_duration_sec=5.0)
    return False


def trajectory_msg(names: Sequence[str], t: np.ndarray, q: np.ndarray,
                   qd: Optional[np.ndarray] = None, qdd: Optional[np.ndarray] = None,
                   start: float = 0.0, frame_id: str = '') -> JointTrajectory:
    """Arrays -> ``JointTrajectory``; ``t`` are times from start, ``start`` the stamp (s)."""
    msg = JointTrajectory()
    msg.header.stamp = to_time(start)
    msg.header.frame_id = frame_id
    msg.joint_names = list(names)
    for k in range(len(t)):
        pt = JointTrajectoryPoint()
        pt.positions = [float(v) for v in q[k]]
        if qd is not None:
            pt.velocities = [float(v) for v in qd[k]]
        if qdd is not None:
            pt.accelerations = [float(v) for v in qdd[k]]
        pt.time_from_start = to_duration(float(t[k]))
        msg.points.append(pt)
    return msg


def move_msg(robot: str, joint_names: Sequence[str],
             cmd: Union[SendMove, HoldArm]) -> JointTrajectory:
    """Return the ``JointTrajectory`` ``robot``'s planner sends for a ``SendMove`` or ``HoldArm``.

    A move (:func:`~scara_collab.core.moves.move_id`) from its start, or the hold
    (:func:`~scara_collab.core.moves.hold_id`) as one point at once (stamp 0); the
    commands are :mod:`scara_collab.core.arm_planner`'s.
    """
    if isinstance(cmd, HoldArm):
        return trajectory_msg(joint_names, np.array([0.0]), cmd.q.reshape(1, 3),
                              frame_id=moves.hold_id(robot))
    t = cmd.plan.traj
    return trajectory_msg(joint_names, t.t, t.q, t.qd, t.qdd, start=cmd.plan.start,
                          frame_id=moves.move_id(robot, cmd.request))


#: the most points a trajectory may have: 100 s at the planners' 100 Hz
MAX_TRAJECTORY_POINTS = 10_000


def trajectory_arrays(msg: JointTrajectory, names: Sequence[str],
                      max_points: int = MAX_TRAJECTORY_POINTS):
    """``JointTrajectory`` -> ``(stamp, t, q, qd or None, qdd or None)`` in ``names`` order.

    ``stamp`` is the header stamp in seconds (0 = start now); ``t`` the times from start.

    :raises MessageError: unknown or missing joint names, mismatched lengths, no points or
        more than ``max_points``, non-monotonic times, non-finite numbers.
    """
    names = list(names)
    if sorted(msg.joint_names) != sorted(names):
        raise MessageError(f'joint names {list(msg.joint_names)} do not match this arm '
                           f'{names}')
    if len(set(msg.joint_names)) != len(msg.joint_names):
        raise MessageError('duplicate joint names')
    if not msg.points:
        raise MessageError('trajectory has no points')
    if len(msg.points) > max_points:
        raise MessageError(f'trajectory has {len(msg.points)} points; at most {max_points} '
                           'are accepted')
    order = [list(msg.joint_names).index(n) for n in names]
    n = len(names)

    def column(field: str, required: bool):
        rows = [getattr(p, field) for p in msg.points]
        if all(len(r) == 0 for r in rows) and not required:
            return None
        bad = [k for k, r in enumerate(rows) if len(r) != n]
        if bad:
            raise MessageError(f'point {bad[0]} has {len(rows[bad[0]])} {field} for {n} joints')
        arr = np.asarray(rows, dtype=float)[:, order]
        if not np.all(np.isfinite(arr)):
            raise MessageError(f'non-finite {field}')
        return arr

    q = column('positions', True)
    qd = column('velocities', False)
    qdd = column('accelerations', False)
    t = np.array([to_sec(p.time_from_start) for p in msg.points])
    if np.any(t < 0) or np.any(np.diff(t) <= 0):
        raise MessageError('time_from_start must be >= 0 and strictly increasing')
    return to_sec(msg.header.stamp), t, q, qd, qdd


def target_frame(frame_id: str, robot: str) -> str:
    """Return the frame of a target for ``robot``'s kinematics: ``'world'`` or ``'base'``.

    ``world`` is the world, ``<robot>_base`` (or ``<robot>_base_link``) the arm's base.

    :raises MessageError: any other frame, with the ones that are understood.
    """
    if frame_id == 'world':
        return 'world'
    if frame_id in (f'{robot}_base', f'{robot}_base_link'):
        return 'base'
    raise MessageError(f'unknown frame {frame_id!r}; use world or {robot}_base')


def point_stamped(msg: PointStamped) -> Tuple[str, np.ndarray, float]:
    """``PointStamped`` -> ``(frame_id, xyz (3,), stamp s)`` (the point may be non-finite)."""
    p = msg.point
    return msg.header.frame_id, np.array([p.x, p.y, p.z], dtype=float), to_sec(msg.header.stamp)


def target_of(msg: PointStamped, robot: str) -> Tuple[np.ndarray, float, str, str]:
    """Return a target for ``robot`` as ``(xyz (3,), stamp s, frame, error)``.

    ``frame`` from :func:`target_frame`, or ``''`` and the reason in ``error`` (the planner
    refuses it so).

    >>> msg = make_point_stamped(np.array([1.0, 2.0, 0.5]), 'elsewhere')
    >>> target_of(msg, 'scara_left')[2:]
    ('', "unknown frame 'elsewhere'; use world or scara_left_base")
    """
    frame_id, xyz, stamp = point_stamped(msg)
    try:
        return xyz, stamp, target_frame(frame_id, robot), ''
    except MessageError as exc:
        return xyz, stamp, '', str(exc)


def offer_of(msg: JointTrajectory, names: Sequence[str]) -> Tuple[tuple, str]:
    """Return an offered plan as ``(trajectory_arrays, '')``, or ``((stamp s,), reason)``."""
    try:
        return trajectory_arrays(msg, names), ''
    except MessageError as exc:
        return (to_sec(msg.header.stamp),), str(exc)


def transform_stamped(parent: str, child: str, pose: np.ndarray,
                      stamp: float) -> TransformStamped:
    """Return the ``TransformStamped`` of ``child`` in ``parent`` (``pose`` ``(4, 4)``).

    >>> t = transform_stamped('world', 'a', np.eye(4), 1.5)
    >>> t.header.frame_id, t.child_frame_id, t.transform.rotation.w, t.header.stamp.sec
    ('world', 'a', 1.0, 1)
    """
    msg = TransformStamped()
    msg.header.stamp = to_time(stamp)
    msg.header.frame_id, msg.child_frame_id = parent, child
    tr = msg.transform.translation
    tr.x, tr.y, tr.z = (float(v) for v in pose[:3, 3])
    rot = msg.transform.rotation
    rot.x, rot.y, rot.z, rot.w = quaternion(pose[:3, :3])
    return msg


def make_point_stamped(xyz, frame_id: str = 'world', stamp: float = 0.0) -> PointStamped:
    """``(3,)`` -> ``PointStamped``."""
    msg = PointStamped()
    msg.header.frame_id = frame_id
    msg.header.stamp = to_time(stamp)
    msg.point = Point(x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
    return msg


def path_msg(points: np.ndarray, stamp: float, frame_id: str = 'world') -> Path:
    """``(N, 3)`` positions -> ``nav_msgs/Path`` (identity orientation)."""
    msg = Path()
    msg.header = Header(stamp=to_time(stamp), frame_id=frame_id)
    for p in points:
        pose = PoseStamped()
        pose.header = msg.header
        pose.pose.position = Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))
        pose.pose.orientation.w = 1.0
        msg.poses.append(pose)
    return msg


def item_markers(items: List, classes: Sequence[str], size: float, stamp: float,
                 frame_id: str = 'world') -> MarkerArray:
    """Items -> ``MarkerArray``: a DELETEALL, then one CUBE per item (``ns`` = class).

    :param items: objects with ``id``, ``cls``, ``position`` (3,).
    """
    header = Header(stamp=to_time(stamp), frame_id=frame_id)
    out = MarkerArray()
    out.markers.append(Marker(header=header, action=Marker.DELETEALL))
    for it in items:
        r, g, b = class_colour(it.cls, classes)
        m = Marker(header=header, ns=it.cls, id=int(it.id), type=Marker.CUBE,
                   action=Marker.ADD, text=it.cls)
        m.pose = Pose()
        m.pose.position = Point(x=float(it.position[0]), y=float(it.position[1]),
                                z=float(it.position[2]))
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = m.scale.z = float(size)
        m.color = ColorRGBA(r=r, g=g, b=b, a=1.0)
        out.markers.append(m)
    return out


def item_positions(msg: MarkerArray) -> Dict[int, Tuple[str, np.ndarray, float]]:
    """Return ``/conveyor/items`` as ``{id: (class, (3,) position, stamp)}``.

    The inverse of :func:`item_markers`: DELETEALL and DELETE are honoured, markers with
    non-finite positions skipped. The class is the marker's ``ns`` (its ``text`` if ``ns``
    is empty).
    """
    items: Dict[int, Tuple[str, np.ndarray, float]] = {}
    for m in msg.markers:
        if m.action == Marker.DELETEALL:
            items.clear()
        elif m.action == Marker.DELETE:
            items.pop(m.id, None)
        elif m.action == Marker.ADD:
            p = m.pose.position
            xyz = np.array([p.x, p.y, p.z], dtype=float)
            if np.all(np.isfinite(xyz)):
                items[int(m.id)] = (m.ns or m.text, xyz, to_sec(m.header.stamp))
    return items


def path_points(msg: Path) -> np.ndarray:
    """``nav_msgs/Path`` -> (N, 3) positions (inverse of :func:`path_msg`)."""
    return np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                     for p in msg.poses], dtype=float).reshape(-1, 3)


def finite(xyz) -> bool:
    """Return ``True`` if every coordinate is finite."""
    return all(math.isfinite(float(v)) for v in xyz)


# --- a person in the cell ----------------------------------------------------------------------
def laser_scan(geometry, ranges: np.ndarray, stamp: float, period: float) -> LaserScan:
    """Return a scanner's ranges as a ``sensor_msgs/LaserScan`` (its ``frame_id``: its name).

    :param geometry: the scanner (:class:`~scara_collab.core.scan_tracking.ScanGeometry`).
    :param ranges: ``(count,)`` m, ``inf`` for no return (REP 117).
    :param stamp: sim time of the scan, s; :param period: s between scans.
    """
    msg = LaserScan(header=Header(stamp=to_time(stamp), frame_id=geometry.name))
    msg.angle_min = float(geometry.angle_min)
    msg.angle_increment = float(geometry.angle_increment)
    msg.angle_max = float(geometry.angle_min + geometry.angle_increment * (geometry.count - 1))
    msg.scan_time = float(period)
    msg.range_min, msg.range_max = float(geometry.range_min), float(geometry.range_max)
    # an array.array('f') is taken as it is; a list is checked float by float (7x the cost)
    msg.ranges = array.array('f', np.asarray(ranges, dtype=np.float32).tobytes())
    return msg


def pose_array(poses: np.ndarray, stamp: float, frame_id: str = 'world') -> PoseArray:
    """``(N, 7)`` positions and quaternions (x, y, z, w) -> ``geometry_msgs/PoseArray``."""
    msg = PoseArray(header=Header(stamp=to_time(stamp), frame_id=frame_id))
    for row in np.asarray(poses, dtype=float).reshape(-1, 7).tolist():
        pose = Pose()
        pose.position = Point(x=row[0], y=row[1], z=row[2])
        (pose.orientation.x, pose.orientation.y, pose.orientation.z,
         pose.orientation.w) = row[3:]
        msg.poses.append(pose)
    return msg


def capsule_markers(poses: np.ndarray, lengths: np.ndarray, radii: np.ndarray, stamp: float,
                    ns: str = 'person', frame_id: str = 'world') -> MarkerArray:
    """Return a body of capsules as markers: a DELETEALL, then cylinders and sphere ends.

    :param poses: ``(N, 7)`` each capsule's centre and the rotation of z onto its axis.
    :param lengths: ``(N,)`` axis lengths (0: a sphere), m; :param radii: ``(N,)`` m.
    """
    header = Header(stamp=to_time(stamp), frame_id=frame_id)
    out = MarkerArray()
    out.markers.append(Marker(header=header, action=Marker.DELETEALL))
    colour = ColorRGBA(r=0.95, g=0.8, b=0.6, a=1.0)
    k = 0
    for row, length, radius in zip(np.asarray(poses, dtype=float).reshape(-1, 7).tolist(),
                                   np.asarray(lengths, dtype=float).tolist(),
                                   np.asarray(radii, dtype=float).tolist()):
        centre, quat = np.array(row[:3]), row[3:]
        axis = _z_turned(quat)
        shapes = [(Marker.CYLINDER, centre, length)] if length > 0.0 else []
        shapes += [(Marker.SPHERE, centre + sign * 0.5 * length * axis, 0.0)
                   for sign in ((-1.0, 1.0) if length > 0.0 else (0.0,))]
        for kind, at, height in shapes:
            m = Marker(header=header, ns=ns, id=k, type=kind, action=Marker.ADD, color=colour)
            m.pose.position = Point(x=float(at[0]), y=float(at[1]), z=float(at[2]))
            (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
             m.pose.orientation.w) = quat
            m.scale.x = m.scale.y = 2.0 * radius
            m.scale.z = height if kind == Marker.CYLINDER else 2.0 * radius
            out.markers.append(m)
            k += 1
    return out


def _z_turned(quat: Sequence[float]) -> np.ndarray:
    """Return the z axis turned by the quaternion ``(x, y, z, w)``."""
    x, y, z, w = quat
    return np.array([2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)])
