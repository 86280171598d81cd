#!/usr/bin/env python3
"""Render a run folder as an animated GIF (PyBullet's headless TinyRenderer camera).

Usage: render_run.py RUN_DIR [--output FILE] [--fps F] [--max-seconds S] [--size WxH]

The arms follow the run's timeseries.csv, the items its run.mcap (/conveyor/items, written by
``launch_cell.py --record``; without it the arms only). Writes RUN_DIR/run.gif by default: a
time-lapse of the job window, at most --max-seconds long. See scara_collab.run.animation.
"""
import sys

from scara_collab.run.animation import main

if __name__ == '__main__':
    sys.exit(main())
