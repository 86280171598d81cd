"""Exact scans for the monitor's tests: rays against vertical circles (legs, pillars)."""
import math

import numpy as np


def scan_circles(geometry, circles, noise=0.0, rng=None):
    """Return the ranges of ``geometry``'s rays against vertical circles ``[(x, y, r), ...]``.

    The exact ray-circle intersection: the nearest hit along each ray, ``inf`` for none;
    Gaussian noise of ``noise`` m (from ``rng``) on the hits.
    """
    d = geometry.directions
    ranges = np.full(geometry.count, np.inf)
    for x, y, r in circles:
        rel = np.array([x, y]) - geometry.origin
        along = d @ rel
        perp_sq = rel @ rel - along ** 2
        hit = (perp_sq <= r * r) & (along > 0)
        dist = along - np.sqrt(np.maximum(r * r - perp_sq, 0.0))
        ranges = np.where(hit & (dist < ranges), dist, ranges)
    if noise:
        finite = np.isfinite(ranges)
        ranges[finite] += rng.normal(0.0, noise, finite.sum())
    return ranges


def legs(x, y, heading=0.0, stance=0.1, radius=0.07, swing=0.0):
    """Return a person's two legs as circles, side by side across ``heading``.

    :param swing: m one foot is ahead (the other behind), as while walking.
    """
    lx, ly = -math.sin(heading) * stance, math.cos(heading) * stance
    fx, fy = math.cos(heading) * swing, math.sin(heading) * swing
    return [(x + lx + fx, y + ly + fy, radius), (x - lx - fx, y - ly - fy, radius)]


def pillars(cell):
    """Return the arms' base pillars as circles (what the empty cell shows a floor scanner)."""
    r = cell.config['arm']['base_radius']
    return [(float(a.base[0, 3]), float(a.base[1, 3]), r) for a in cell.arms]
