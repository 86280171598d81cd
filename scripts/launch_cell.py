#!/usr/bin/env python3
"""Launch the scara_collab cell on sim time, run the sorting job, record and report it.

Usage: launch_cell.py [--mode idle|single|collaborative|mirrored] [--duration SIM_SECONDS]
                      [--rtf FACTOR] [--gui] [--output DIR] [--profile P] [--seed N] [--quiet]
                      [--viewer [PORT]] [--record] [--animation] [--lockstep on|off]
                      [--namespace NS]

Starts pybullet_bridge, left_planner, right_planner, replication_manager, collision_monitor and
automation_manager (and with --viewer the cell_viewer) as separate processes, in that order,
each once the previous one is ready on the graph; records the run into the output folder
(timeseries.csv, events.csv, summary.json, plots, logs/<node>.log; run.mcap with --record,
run.gif with --animation) and prints a report. --lockstep off runs the nodes against a clock
that waits for nobody (real time, as on hardware or in Gazebo). --namespace /cell_1 runs the
whole cell under /cell_1, so cells in different namespaces share a ROS domain. See
scara_collab.run.launcher.
"""
import sys

try:
    from scara_collab.run.launcher import main
except ImportError:  # a source checkout that is not installed: use the tree beside this file
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from scara_collab.run.launcher import main

if __name__ == '__main__':
    sys.exit(main())
