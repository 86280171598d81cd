"""Benchmarks: measure what the design documents claim, on this machine.

One module per section, its measurement and its presentation together: the numbered sections
of ``docs/RESULTS.md`` (:mod:`~scara_collab.bench.paths`, :mod:`~scara_collab.bench.solvers`,
:mod:`~scara_collab.bench.payload`, :mod:`~scara_collab.bench.sync`,
:mod:`~scara_collab.bench.singularity`, :mod:`~scara_collab.bench.foresight`,
:mod:`~scara_collab.bench.throughput`, with :mod:`~scara_collab.bench.job` and
:mod:`~scara_collab.bench.capacity`), run and written by :mod:`~scara_collab.bench.report`;
and the runs through the launcher (:mod:`~scara_collab.bench.protocol`,
:mod:`~scara_collab.bench.faults`, :mod:`~scara_collab.bench.soak`,
:mod:`~scara_collab.bench.realtime`). ``scripts/benchmark.py --only SECTION`` runs any of
them. :mod:`~scara_collab.bench.util` holds what they share (timing, progress, Markdown,
figures); :mod:`~scara_collab.bench.claims` the seeds' quoted claims.

Figures are measurements, never assertions: nothing here fails because a number is slow.
"""
