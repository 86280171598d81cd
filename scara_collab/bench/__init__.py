"""Benchmarks: measure what the design documents claim, on this machine, in one run.

Each module measures one thing and returns plain data (dicts of floats, lists, strings) that
the scripts print and :mod:`scara_collab.bench.report` turns into ``docs/RESULTS.md``:

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
- :mod:`~scara_collab.bench.job`: the sorting job, in one process or through the launcher;
- :mod:`~scara_collab.bench.suite`: all of them with progress lines, figures and the report.

Figures are measurements, never assertions: nothing here fails because a number is slow.
"""
