"""The simulated safety laser scanner: ranges from ray casts in the cell's PyBullet world.

Each scanner (:class:`~scara_collab.core.scan_tracking.ScanGeometry`, ``config/people.yaml``)
casts its rays in a horizontal plane ``height`` above the floor, across its field of view, in
one ``rayTestBatch`` call of the world's client (the :class:`~scara_collab.sim.cell_sim.CellSim`'s;
no client of its own). A ray's range is the hit fraction times ``range_max`` plus Gaussian
noise (``noise``, seeded), ``inf`` where nothing is hit (REP 117: no return), never below
``range_min``. With ``ghost_probability`` > 0 a ray now and then returns a spurious range short
of what it hit (a ghost point, as dust or a reflection gives a real scanner).

The scanner sees everything in the world at its height: the pillars under the arms, a person's
legs, a quill or an item crossing the plane. What belongs to the empty cell is taught to the
monitor as its contour (:meth:`SafetyScanner.scan` with the person parked); the rest is the
monitor's to sort out (:mod:`scara_collab.core.scan_tracking`).

Only the rays that something may have changed are cast again (a physics engine's culling,
exact): at each scan the scanner takes the bounding box of every link of every body in the
world (``getAABB``); every ray that crosses, in a scan plane, the box of a link that moved,
came or went since the last scan (where it was and where it is) is cast, found by the box's
bearings with a ray to spare on each side (:func:`rays_towards`); every other ray's range is
the one it had, nothing on its way having changed. The first scan casts every ray. The ranges
are identical to the bit to casting every ray every time (``test_scanner``): the culling makes
the scanner cheaper, never different. A scan of a still cell costs a few hundredths of a
millisecond of bounding boxes; a quill moving through the plane (at every pick and drop) or a
person walking adds the rays across them.
"""
import math
from typing import Dict, List, Sequence, Tuple

import numpy as np

from scara_collab.core.scan_tracking import ScanGeometry, scanners_from_config

#: m a link's box is grown by before rays are tested against it (a ray grazing its corner)
BOX_PAD = 1e-3
#: (min corner, max corner) of a link's bounding box, world, m
Box = Tuple[Tuple[float, float, float], Tuple[float, float, float]]


def rays_towards(geometry: ScanGeometry, boxes: Sequence[Sequence[float]]) -> np.ndarray:
    """Return which rays of a scanner may cross some rectangles on the floor plan.

    A rectangle not around the scanner is seen under an angle of less than half a turn, its
    corners' bearings bounding it: every ray whose bearing lies within (one ray more on each
    side, for rounding) may cross it; a rectangle around the scanner, every ray. A superset of
    the rays that cross (the ray's length is not looked at): casting them again changes no
    range that casting every ray would not. ``O(B)`` bearings, not a test per ray and box.

    :param geometry: the scanner; :param boxes: ``(xmin, ymin, xmax, ymax)`` each, m.
    :return: ``(count,)`` bool.

    >>> g = ScanGeometry('s', 0.0, 0.0, 0.0, -np.pi / 2, np.pi / 180, 181, 0.05, 20.0, 0.3)
    >>> np.flatnonzero(rays_towards(g, np.array([[2.0, -0.1, 3.0, 0.1]])))  # dead ahead
    array([87, 88, 89, 90, 91, 92, 93])
    >>> int(rays_towards(g, np.array([[-1.0, -1.0, 1.0, 1.0]])).sum())  # around the scanner
    181
    """
    out = np.zeros(geometry.count, dtype=bool)
    x, y, first = geometry.x, geometry.y, geometry.yaw + geometry.angle_min
    inc, count = geometry.angle_increment, geometry.count
    turn = 2.0 * math.pi / inc
    for x0, y0, x1, y1 in boxes:  # a few boxes: plain floats
        x0, y0, x1, y1 = x0 - x, y0 - y, x1 - x, y1 - y
        if x0 <= 0.0 <= x1 and y0 <= 0.0 <= y1:  # around the scanner
            out[:] = True
            return out
        bearings = [math.atan2(b, a) for a, b in ((x0, y0), (x1, y0), (x0, y1), (x1, y1))]
        # the corners from the first one's bearing, within half a turn of it
        offsets = [(b - bearings[0] + math.pi) % (2.0 * math.pi) - math.pi for b in bearings]
        low = (bearings[0] + min(offsets) - first) % (2.0 * math.pi) / inc  # in rays from ray 0
        high = low + (max(offsets) - min(offsets)) / inc
        for shift in (0.0, -turn):  # a span across ray 0's bearing: also from a turn before
            k0, k1 = math.ceil(low + shift) - 1, math.floor(high + shift) + 1
            if k1 >= 0 and k0 < count:
                out[max(k0, 0):min(k1, count - 1) + 1] = True
    return out


class SafetyScanner:
    """One or more floor scanners in a PyBullet world.

    :param pb: the world's client.
    :param scanners: their geometry (pose, rays, ranges, height).
    :param rate: scans per second, Hz.
    :param noise: m, 1 sigma of the range noise.
    :param seed: the noise's seed.
    :param ghost_probability: per ray and scan, the chance of a spurious short return.
    :param cull: cast only the rays something may have changed (False: every ray, every scan:
        the reference the culling is tested against).
    """

    def __init__(self, pb, scanners: Sequence[ScanGeometry], rate: float, noise: float = 0.0,
                 seed: int = 0, ghost_probability: float = 0.0, cull: bool = True):
        """Precompute every ray's ends (the rays never move)."""
        self.pb = pb
        self.scanners = tuple(scanners)
        self.period = 1.0 / float(rate)
        self.noise, self.ghost_probability = float(noise), float(ghost_probability)
        self.cull = bool(cull)
        self.rng = np.random.default_rng(seed)
        self._rays = []
        for g in self.scanners:
            start = np.column_stack([np.full(g.count, g.x), np.full(g.count, g.y),
                                     np.full(g.count, g.height)])
            end = start.copy()
            end[:, :2] += g.range_max * g.directions
            self._rays.append((start, end))
        #: per scanner the noiseless ranges of the last scan (None: none yet), m
        self._ranges: List[np.ndarray] = [None] * len(self.scanners)
        #: every link's bounding box at the last scan, by (body, link)
        self._boxes: Dict[Tuple[int, int], Box] = {}
        #: rays cast by the last scan (the culling's measure)
        self.cast = 0

    @staticmethod
    def from_config(pb, cfg: dict) -> 'SafetyScanner':
        """Build it from the validated ``people`` config (section ``scanner``)."""
        sc = cfg['scanner']
        return SafetyScanner(pb, scanners_from_config(cfg), float(sc['rate']), float(sc['noise']),
                             int(sc['seed']), float(sc['ghost_probability']))

    def _changed(self) -> List[Box]:
        """Return the boxes of the links that moved, came or went since the last scan.

        Of a link that moved, both its box then and its box now; every link of every body in
        the world is looked at (bodies come and go: items, the person).
        """
        pb, boxes, changed = self.pb, {}, []
        body_id, links, aabb = pb.getBodyUniqueId, pb.getNumJoints, pb.getAABB  # looked up once
        for i in range(pb.getNumBodies()):
            body = body_id(i)
            for link in range(-1, links(body)):
                box = aabb(body, link)
                key = (body, link)
                boxes[key] = box
                then = self._boxes.pop(key, None)
                if then != box:
                    changed.append(box)
                    if then is not None:
                        changed.append(then)
        changed.extend(self._boxes.values())  # gone since
        self._boxes = boxes
        return changed

    def _to_cast(self, k: int, changed: Sequence[Box]) -> np.ndarray:
        """Return which rays of scanner ``k`` a changed box may have changed, ``(count,)``."""
        g = self.scanners[k]
        if self._ranges[k] is None or not self.cull:
            return np.ones(g.count, dtype=bool)
        pad = BOX_PAD
        return rays_towards(g, [(lo[0] - pad, lo[1] - pad, hi[0] + pad, hi[1] + pad)
                                for lo, hi in changed if lo[2] - pad <= g.height <= hi[2] + pad])

    def scan(self) -> List[np.ndarray]:
        """Cast the scanners' rays now; return their ranges, ``(count,)`` each, m.

        Every scanner's rays to cast go in one ``rayTestBatch`` (each call has a cost of its
        own, several times a ray's).
        """
        out = []
        changed = self._changed() if self.cull else []
        casts = [self._to_cast(k, changed) for k in range(len(self.scanners))]
        start = np.concatenate([s[c] for (s, _), c in zip(self._rays, casts)])
        end = np.concatenate([e[c] for (_, e), c in zip(self._rays, casts)])
        self.cast = len(start)
        fraction = np.zeros(0)
        if self.cast:
            hits = self.pb.rayTestBatch(start.tolist(), end.tolist())
            fraction = np.fromiter((h[2] if h[0] >= 0 else np.inf for h in hits), float,
                                   len(hits))
        first = 0
        for k, (g, cast) in enumerate(zip(self.scanners, casts)):
            if self._ranges[k] is None:
                self._ranges[k] = np.full(g.count, np.inf)
            n = int(np.count_nonzero(cast))
            if n:
                self._ranges[k][cast] = fraction[first:first + n] * g.range_max
                first += n
            ranges = self._ranges[k].copy()
            hit = np.isfinite(ranges)
            if self.noise > 0.0:
                ranges[hit] += self.rng.normal(0.0, self.noise, int(hit.sum()))
            if self.ghost_probability > 0.0:
                ghost = self.rng.random(g.count) < self.ghost_probability
                if ghost.any():
                    far = np.where(hit[ghost], ranges[ghost], g.range_max)
                    ranges[ghost] = g.range_min + self.rng.random(int(ghost.sum())) * (
                        far - g.range_min)
            ranges[np.isfinite(ranges)] = np.maximum(ranges[np.isfinite(ranges)], g.range_min)
            out.append(ranges)
        return out
