"""Running the cell: the launcher and the run's processes.

- :mod:`scara_collab.run.launcher`: ``scripts/launch_cell.py``, the whole graph in order, the
  run (:mod:`~scara_collab.run.options` for its command line,
  :mod:`~scara_collab.run.stages`, :mod:`~scara_collab.run.supervisor` for the child
  processes, :mod:`~scara_collab.run.liveness` for their lockstep answers,
  :mod:`~scara_collab.run.graph_client` for waits, calls and readiness,
  :mod:`~scara_collab.run.console`);
- :mod:`scara_collab.run.child`: how the launcher starts one node executable;
- :mod:`scara_collab.run.container`: the graph in one process;
- :mod:`scara_collab.run.animation`: a run's GIF from its MCAP recording.

The run's files (CSV, summary, plots, MCAP) are :mod:`scara_collab.records`' (no rclpy); the
``run_recorder`` node that writes them is :mod:`scara_collab.nodes.recorder`.
"""
