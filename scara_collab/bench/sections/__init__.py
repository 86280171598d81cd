"""The sections of the benchmark, one module each, registered here in report order.

A section (:class:`~scara_collab.bench.sections.base.Section`) is everything one part of
``RESULTS.md`` needs, in one module: its sizes (full and smoke run), ``measure`` (calls the
measurement module, e.g. :mod:`scara_collab.bench.paths`, which the ``scripts/bench_*.py``
share), its summary rows, its Markdown and its figure. :func:`scara_collab.bench.suite.run`
measures and draws them in the order of :data:`SECTIONS`;
:func:`scara_collab.bench.report.render` numbers and writes them in that order.

To add a section: write ``sections/<key>.py`` ending in ``SECTION = Section(...)`` (the
others are the pattern) and add it to :data:`SECTIONS`, and to :data:`SUMMARY_ORDER` if it
has summary rows.
"""
from typing import Tuple

from scara_collab.bench.sections import (
    foresight, paths, payload, singularity, solvers, sync, throughput)
from scara_collab.bench.sections.base import Section

SECTIONS: Tuple[Section, ...] = (
    paths.SECTION, solvers.SECTION, payload.SECTION, sync.SECTION, singularity.SECTION,
    foresight.SECTION, throughput.SECTION)
"""Every section, in the order they run and appear (numbered) in ``RESULTS.md``."""

SUMMARY_ORDER: Tuple[str, ...] = (
    'solvers', 'paths', 'sync', 'payload', 'singularity', 'foresight', 'throughput')
"""The keys of the sections whose rows make the summary table, in its order (IK first)."""
