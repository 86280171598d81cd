"""Benchmarks: measure what the design documents claim, on this machine.

One module per section, its measurement and its presentation together; ``report`` runs the
numbered sections of ``docs/RESULTS.md``, ``scripts/benchmark.py --only SECTION`` any of them.
Figures are measurements, never assertions: nothing here fails because a number is slow.
"""
