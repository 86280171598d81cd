"""Running the cell: the launcher, the run recorder and the run report.

- :mod:`scara_collab.run.telemetry`: the files of one run and their numbers (no rclpy);
- :mod:`scara_collab.run.recorder`: the ``run_recorder`` node that feeds them from the graph;
- :mod:`scara_collab.run.report`: ``summary.json``, the plots and the printed report;
- :mod:`scara_collab.run.launcher`: ``scripts/launch_cell.py``, the whole graph in order;
- :mod:`scara_collab.run.child`: how the launcher starts one node executable.
"""
