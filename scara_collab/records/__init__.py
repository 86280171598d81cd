"""A run's files, without rclpy: what the recorder nodes write and the scripts read.

``telemetry`` (the joint-state time series and its figures, the CSV files), ``record`` (the
run's record: job window, counts, summary), ``report`` (the plots and the text report),
``mcap_log`` (the MCAP recording: schemas, writer, reader), ``person`` (a run with a person:
the summary's ``person`` block, its CSV files). The rclpy side is
:mod:`scara_collab.nodes.recorder` and :mod:`scara_collab.nodes.mcap_recorder`; the launcher
(:mod:`scara_collab.run`) and the scripts read the files back.
"""
