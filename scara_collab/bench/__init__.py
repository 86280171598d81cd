"""Benchmarks: measure what the design documents claim, on this machine, in one run.

Each measurement module measures one thing and returns plain data (dicts of floats, lists,
strings) that the ``scripts/bench_*.py`` print:

- :mod:`~scara_collab.bench.solvers`: IK, Jacobian, dynamics, collision distance, against
  reference implementations (a textbook numpy IK, Pinocchio, coal) in the same process;
- :mod:`~scara_collab.bench.paths`: straight line vs joint interpolation, planned and
  executed in physics;
- :mod:`~scara_collab.bench.physics`: simulator speed and payload tracking (PID vs computed
  torque);
- :mod:`~scara_collab.bench.graph`: mirrored moves through the ROS graph (mirror error, lag);
- :mod:`~scara_collab.bench.singularity`: pseudo-inverse vs damped least squares near the
  singularities;
- :mod:`~scara_collab.bench.foresight`: conflict detection and resolution for crossing moves;
- :mod:`~scara_collab.bench.job`, :mod:`~scara_collab.bench.capacity`: the sorting job, in
  one process or through the launcher, and what bounds its capacity.

The one-command benchmark (``scripts/benchmark.py``) is made of sections,
:mod:`scara_collab.bench.sections`, one module each: a section runs its measurement with its
sizes and holds its summary rows, its Markdown and its figure.
:mod:`~scara_collab.bench.suite` runs them with progress lines;
:mod:`~scara_collab.bench.report` writes the page around them (``docs/RESULTS.md``) with
:mod:`~scara_collab.bench.markdown` and :mod:`~scara_collab.bench.figures`, the helpers they
share. The launcher's fault matrix, soak and job protocol (:mod:`~scara_collab.bench.faults`,
:mod:`~scara_collab.bench.soak`, :mod:`~scara_collab.bench.protocol`) have scripts of their
own that write their blocks into the same page.

Figures are measurements, never assertions: nothing here fails because a number is slow.
"""
