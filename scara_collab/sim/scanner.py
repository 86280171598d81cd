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

A scan (both scanners, 541 rays each) costs about 0.35 ms of CPU per scanner on the project's
machine: at 25 Hz, under 20 ms per sim second (``test_scanner`` measures it).
"""
from typing import List, Sequence

import numpy as np

from scara_collab.core.scan_tracking import ScanGeometry, scanners_from_config


class SafetyScanner:
    """One or more floor scanners in a PyBullet world.

    :param pb: the world's client.
    :param scanners: their geometry (pose, rays, ranges, height).
    :param rate: scans per second, Hz.
    :param noise: m, 1 sigma of the range noise.
    :param seed: the noise's seed.
    :param ghost_probability: per ray and scan, the chance of a spurious short return.
    """

    def __init__(self, pb, scanners: Sequence[ScanGeometry], rate: float, noise: float = 0.0,
                 seed: int = 0, ghost_probability: float = 0.0):
        """Precompute every ray's ends (the rays never move)."""
        self.pb = pb
        self.scanners = tuple(scanners)
        self.period = 1.0 / float(rate)
        self.noise, self.ghost_probability = float(noise), float(ghost_probability)
        self.rng = np.random.default_rng(seed)
        self._rays = []
        for g in self.scanners:
            start = np.column_stack([np.full(g.count, g.x), np.full(g.count, g.y),
                                     np.full(g.count, g.height)])
            end = start.copy()
            end[:, :2] += g.range_max * g.directions
            self._rays.append((start.tolist(), end.tolist()))

    @staticmethod
    def from_config(pb, cfg: dict) -> 'SafetyScanner':
        """Build it from the validated ``people`` config (section ``scanner``)."""
        sc = cfg['scanner']
        return SafetyScanner(pb, scanners_from_config(cfg), float(sc['rate']), float(sc['noise']),
                             int(sc['seed']), float(sc['ghost_probability']))

    def scan(self) -> List[np.ndarray]:
        """Cast every scanner's rays now; return their ranges, ``(count,)`` each, m."""
        out = []
        for g, (start, end) in zip(self.scanners, self._rays):
            hits = self.pb.rayTestBatch(start, end)
            fraction = np.fromiter((h[2] if h[0] >= 0 else np.inf for h in hits), float,
                                   g.count)
            ranges = fraction * g.range_max
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
