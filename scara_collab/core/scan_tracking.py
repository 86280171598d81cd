"""From safety laser scans to tracked persons, without ROS: contour, foreground, clusters, tracks.

A safety laser scanner measures ranges in a horizontal plane (``sensor_msgs/LaserScan``:
``angle_min``, ``angle_increment``, ``ranges``; REP 117: ``+inf`` for no return, ``-inf`` for
too close, NaN for an invalid measurement). The monitor finds persons in them as a safety
scanner does with its fields, from the ranges alone:

1. **Contour.** With the cell empty, the scanner is taught the ranges of everything static
   (the pillars, the belt frame, the bins): per ray the shortest range over a few scans
   (:func:`teach_contour`; ``inf`` where no scan had a return).
2. **Foreground.** A return is a candidate where it falls short of the contour by more than a
   threshold (:func:`foreground`); its point in the world follows from the scanner's pose
   (:meth:`ScanGeometry.points`).
3. **Muting.** Candidates where no one can stand are dropped (:func:`inside_boxes`): the belt
   and the bins, where items and the arms' quills cross the scan plane, and a disc around each
   arm's quill axis (:func:`near_points`): a quill lowered into the plane, or the item it
   carries, is the arm itself.
4. **Clusters.** Candidates closer than a gap form one person, both legs together
   (:func:`clusters`, single linkage).
5. **Tracks.** :class:`Tracker` follows each person from scan to scan: its position is the
   cluster's centre, its velocity a least-squares fit over the last fraction of a second. A
   cluster of fewer returns than ``min_points`` is a person only where one was seen just
   before (a track or a small cluster of the previous scan): a single ghost point never is, a
   far person seen by one ray per leg still is. A person no longer seen is kept for a while
   where last seen, the monitor growing its column at walking speed.

Everything is numpy on arrays; times are parameters (sim seconds). This is a simulation of a
safety function, not a certified one.
"""
from dataclasses import dataclass, field
from functools import cached_property
import math
from typing import List, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class ScanGeometry:
    """Where a scanner is and how it scans (what a ``LaserScan`` header and limits say).

    :ivar name: the scanner's name (its frame id).
    :ivar x, y, yaw: its pose on the floor, world, m and rad.
    :ivar angle_min: angle of the first ray in the scanner's frame, rad.
    :ivar angle_increment: between rays, rad.
    :ivar count: number of rays.
    :ivar range_min, range_max: the valid ranges, m.
    :ivar height: the scan plane above the floor, m.
    """

    name: str
    x: float
    y: float
    yaw: float
    angle_min: float
    angle_increment: float
    count: int
    range_min: float
    range_max: float
    height: float

    @cached_property
    def directions(self) -> np.ndarray:
        """Unit vectors of the rays in world, ``(count, 2)``."""
        a = self.yaw + self.angle_min + self.angle_increment * np.arange(self.count)
        return np.column_stack([np.cos(a), np.sin(a)])

    @property
    def origin(self) -> np.ndarray:
        """The scanner's position on the floor, ``(2,)``, world."""
        return np.array([self.x, self.y])

    def points(self, ranges: np.ndarray, mask: Optional[np.ndarray] = None) -> np.ndarray:
        """Return the world points ``(M, 2)`` of the rays ``mask`` selects (default: all)."""
        if mask is None:
            return self.origin + ranges[:, None] * self.directions
        return self.origin + ranges[mask, None] * self.directions[mask]


def scanners_from_config(cfg: dict) -> Tuple[ScanGeometry, ...]:
    """Return the scanners of the validated ``people`` config (section ``scanner``).

    The field of view is centred on the scanner's yaw, ``rays`` rays from edge to edge.
    """
    sc = cfg['scanner']
    fov, rays = float(sc['field_of_view']), int(sc['rays'])
    out = []
    for name in sc['names']:
        x, y, yaw = (float(v) for v in sc[name]['pose'])
        out.append(ScanGeometry(name, x, y, yaw, -fov / 2.0, fov / (rays - 1), rays,
                                float(sc['range_min']), float(sc['range_max']),
                                float(sc['height'])))
    return tuple(out)


def range_faults(ranges: np.ndarray, geometry: ScanGeometry) -> int:
    """Return the number of rays that measured nothing usable: NaN, ``-inf``, below range_min.

    A safety scanner that cannot measure (dazzled, dirty window, something on it) switches its
    outputs off; the monitor does the same with any such ray. A scan of the wrong length counts
    every ray.
    """
    ranges = np.asarray(ranges, dtype=float)
    if ranges.shape != (geometry.count,):
        return geometry.count
    with np.errstate(invalid='ignore'):
        return int(np.count_nonzero(np.isnan(ranges) | (ranges < geometry.range_min)))


def teach_contour(scans: ArrayLike, range_max: float = math.inf) -> np.ndarray:
    """Return the contour of the empty cell: per ray the shortest return of ``scans``.

    :param scans: ``(K, N)`` ranges of K scans, ``inf`` for no return.
    :param range_max: returns beyond it count as none.
    :return: ``(N,)`` m; ``inf`` where no scan had a return.

    >>> teach_contour([[2.0, np.inf, 5.0], [1.9, np.inf, 25.0]], range_max=20.0)
    array([1.9, inf, 5. ])
    """
    scans = np.asarray(scans, dtype=float)
    scans = np.where(np.isfinite(scans) & (scans <= range_max), scans, np.inf)
    return scans.min(axis=0)


def foreground(ranges: np.ndarray, contour: np.ndarray, threshold: float,
               range_max: float) -> np.ndarray:
    """Return which rays hit something in front of the taught contour, ``(N,)`` bool.

    A finite return within ``range_max`` that is shorter than the contour by more than
    ``threshold`` (every return where the contour had none).
    """
    with np.errstate(invalid='ignore'):
        return np.isfinite(ranges) & (ranges <= range_max) & (ranges < contour - threshold)


def inside_boxes(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Return which points ``(M, 2)`` lie inside any box ``(B, 4)`` ``[x0, x1, y0, y1]``."""
    if len(boxes) == 0 or len(points) == 0:
        return np.zeros(len(points), dtype=bool)
    x, y = points[:, 0, None], points[:, 1, None]
    return np.any((x >= boxes[:, 0]) & (x <= boxes[:, 1]) & (y >= boxes[:, 2])
                  & (y <= boxes[:, 3]), axis=1)


def near_points(points: np.ndarray, centres: np.ndarray, radius: float) -> np.ndarray:
    """Return which points ``(M, 2)`` are within ``radius`` of any centre ``(C, 2)``."""
    if len(centres) == 0 or len(points) == 0 or radius <= 0.0:
        return np.zeros(len(points), dtype=bool)
    d = points[:, None, :] - centres[None, :, :]
    return np.any(np.einsum('mcj,mcj->mc', d, d) <= radius * radius, axis=1)


def cell_mute_boxes(cell, margin: float) -> np.ndarray:
    """Return the floor boxes where no one stands: the belt and the bins, grown by ``margin``.

    :param cell: the :class:`~scara_collab.core.model.CellModel`.
    :return: ``(B, 4)`` boxes ``[x0, x1, y0, y1]``, world, m.
    """
    belt = cell.belt
    half = belt.width / 2.0 + margin
    boxes = [[belt.x_start - margin, belt.x_end + margin, belt.centre_y - half,
              belt.centre_y + half]]
    size = cell.config['bins']['size']
    for centre in cell.bins.values():
        boxes.append([centre[0] - size[0] / 2.0 - margin, centre[0] + size[0] / 2.0 + margin,
                      centre[1] - size[1] / 2.0 - margin, centre[1] + size[1] / 2.0 + margin])
    return np.array(boxes, dtype=float)


@dataclass(frozen=True)
class Cluster:
    """Returns that belong to one person.

    :ivar centre: ``(2,)`` the mean of its points, world, m.
    :ivar radius: m, its farthest point from the centre.
    :ivar count: its number of returns.
    """

    centre: np.ndarray
    radius: float
    count: int


def clusters(points: np.ndarray, gap: float) -> List[Cluster]:
    """Group points closer than ``gap`` (single linkage): one cluster per connected group.

    :param points: ``(M, 2)`` world points.
    :return: the clusters, in the order of their first point.

    >>> [c.count for c in clusters(np.array([[0, 0], [0.3, 0], [0.6, 0], [5, 5]]), 0.4)]
    [3, 1]
    """
    m = len(points)
    if m == 0:
        return []
    d = points[:, None, :] - points[None, :, :]
    linked = np.einsum('ijk,ijk->ij', d, d) <= gap * gap
    labels = np.arange(m)
    while True:  # each point takes the smallest label it is linked to, until none changes
        new = np.where(linked, labels[None, :], m).min(axis=1)
        if np.array_equal(new, labels):
            break
        labels = new
    out = []
    for label in np.unique(labels):
        pts = points[labels == label]
        centre = pts.mean(axis=0)
        out.append(Cluster(centre, float(np.sqrt(((pts - centre) ** 2).sum(axis=1)).max()),
                           len(pts)))
    return out


@dataclass
class Track:
    """A person followed from scan to scan (:class:`Tracker`).

    :ivar id: its number (from 1).
    :ivar position: ``(2,)`` where it was last seen, world, m.
    :ivar radius: m, its cluster's radius when last seen.
    :ivar seen: when it was last seen, s.
    :ivar times, positions: its recent history (for the velocity).
    """

    id: int
    position: np.ndarray
    radius: float
    seen: float
    times: List[float] = field(default_factory=list)
    positions: List[np.ndarray] = field(default_factory=list)

    def velocity(self, window: float) -> np.ndarray:
        """Return the least-squares velocity over the last ``window`` s, ``(2,)`` m/s.

        Zeros with fewer than three positions or less than half the window of history (the
        monitor then assumes the walking speed).
        """
        t = np.array(self.times)
        keep = t >= self.seen - window
        t = t[keep]
        if len(t) < 3 or t[-1] - t[0] < window / 2.0:
            return np.zeros(2)
        p = np.array(self.positions)[keep]
        tc = t - t.mean()
        return (tc[:, None] * (p - p.mean(axis=0))).sum(axis=0) / (tc * tc).sum()


class Tracker:
    """Persons from the clusters of each scan: association, velocity, ghost rejection.

    :param gate: m a person moves between two scans at most (a cluster farther from every
        track starts a new one).
    :param hold: s a track no longer seen is kept.
    :param window: s of history for the velocity.
    :param min_points: fewer returns make a cluster count only near a track or near a small
        cluster of the previous scan.
    """

    def __init__(self, gate: float, hold: float, window: float, min_points: int):
        """Start with no track."""
        self.gate, self.hold, self.window, self.min_points = gate, hold, window, min_points
        self.tracks: List[Track] = []
        self._small: np.ndarray = np.zeros((0, 2))
        self._next_id = 1

    def update(self, stamp: float, found: Sequence[Cluster]) -> List[Track]:
        """Take the clusters of the scans at ``stamp``; return the tracks (seen and held).

        Clusters are matched to tracks greedily, nearest first, within the gate; a track is
        matched once. Unmatched clusters start tracks.
        """
        centres = np.array([c.centre for c in found]).reshape(-1, 2)
        known = np.array([t.position for t in self.tracks]).reshape(-1, 2)
        small = np.array([c.count < self.min_points for c in found], dtype=bool)
        confirmed = ~small
        if small.any():
            near = np.vstack([known, self._small])
            confirmed |= small & near_points(centres, near, self.gate)
        self._small = centres[small]
        if len(known) and len(centres):
            d = np.linalg.norm(centres[:, None, :] - known[None, :, :], axis=-1)
            d[~confirmed] = np.inf
        else:
            d = np.full((len(centres), len(known)), np.inf)
        matched = set()
        for flat in np.argsort(d, axis=None):
            i, j = np.unravel_index(flat, d.shape)
            if d[i, j] > self.gate:
                break
            if i in matched or self.tracks[j].seen == stamp:
                continue
            matched.add(i)
            self._see(self.tracks[j], stamp, found[i])
        for i, c in enumerate(found):
            if confirmed[i] and i not in matched:
                track = Track(self._next_id, c.centre, c.radius, stamp)
                self._next_id += 1
                self._see(track, stamp, c)
                self.tracks.append(track)
        self.tracks = [t for t in self.tracks if stamp - t.seen <= self.hold]
        return list(self.tracks)

    def _see(self, track: Track, stamp: float, cluster: Cluster) -> None:
        track.position, track.radius, track.seen = cluster.centre, cluster.radius, stamp
        track.times.append(stamp)
        track.positions.append(cluster.centre)
        while track.times and track.times[0] < stamp - self.window:
            track.times.pop(0)
            track.positions.pop(0)
