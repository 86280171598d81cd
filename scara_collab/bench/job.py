"""The sorting job, measured in one process (:func:`run_job`).

:func:`run_job` builds the whole graph in ONE process on one executor, unthrottled: sim time
cannot run ahead of the nodes while they compute, so the figures are the job's own, free of
the latency separate processes add. The bridge's lockstep gate stays on: even in one process
messages travel through DDS asynchronously, and without the gate a loaded machine lets the
bridge step on before they arrive. Through the launcher: :mod:`scara_collab.bench.launched`.
"""
import time
from typing import Callable, Dict, Optional, Sequence

from scara_collab import graph
from scara_collab.bench.util import Log
from scara_collab.core.config import load_config
from scara_collab.nodes.runner import InProcess


def default_feed() -> float:
    """Seconds between items of ``simulation.yaml`` (the feed every mode uses)."""
    return float(load_config('simulation')['feed_interval'])


def run_job(mode: str, duration: float, feed: Optional[float] = None,
            seed: Optional[int] = None, log: Optional[Log] = None,
            report_every: float = 10.0, faults: Sequence[str] = (),
            during: Optional[Callable[[InProcess, Dict[str, object], float], None]] = None
            ) -> Dict[str, object]:
    """Run one mode for ``duration`` sim seconds in one process; return the job's figures.

    :param mode: ``'single'``, ``'collaborative'`` or ``'mirrored'``.
    :param feed: sim seconds between items (default: ``simulation.yaml``).
    :param seed: item feed seed (default ``simulation.yaml``).
    :param report_every: sim seconds between progress lines.
    :param faults: fault injection entries for every node (:mod:`scara_collab.nodes.faults`).
    :param during: called as ``during(g, nodes, sim_time)`` after every turn of the executor
        (``g`` the :class:`~scara_collab.nodes.runner.InProcess` graph, ``nodes`` by name).
    :return: counts, ``items_per_minute``, ``give_ups``, ``retries``, ``min_separation_m``,
        stops, the mirror error (mirrored mode), ``wall_seconds``, ``sim_seconds``,
        ``real_time_factor``, ``feed_interval``, ``seed``.
    """
    feed = default_feed() if feed is None else float(feed)
    seed = int(load_config('simulation')['item_seed'] if seed is None else seed)
    g = InProcess()
    params = graph.job_params(mode)  # as the launcher starts them
    params['pybullet_bridge'].update(real_time_factor=0.0, feed_interval=feed, item_seed=seed,
                                     lockstep_expect=graph.lockstep_expect(graph.job_nodes()))
    params['automation_manager']['auto_start'] = 'true'
    nodes = {}
    for spec in graph.job_nodes():
        own = dict(params[spec.name], **({'faults': list(faults)} if faults else {}))
        nodes[spec.name] = g.add(spec.build(context=g.context,
                                            cli_args=graph.ros_args(spec.configs, own)))
    bridge, job = nodes['pybullet_bridge'], nodes['automation_manager']
    wall = time.monotonic()
    next_report = report_every
    try:
        while bridge.sim.time < duration:
            g.spin_once(timeout_sec=0.01)
            if during is not None:
                during(g, nodes, bridge.sim.time)
            if log and bridge.sim.time >= next_report:
                c = job.job.counts
                log(f'{mode} (seed {seed}): {bridge.sim.time:.0f}/{duration:.0f} sim s, sorted '
                    f'{c.get("sorted", 0)}, missed {c.get("missed", 0)}, '
                    f'{time.monotonic() - wall:.0f} s wall')
                next_report += report_every
        stats, took = job.stats(), time.monotonic() - wall
        mirror = nodes['replication_manager'].status()
        guard = nodes['collision_monitor'].status()
        return {'mode': stats.mode, **stats.counts, 'items_per_minute': stats.items_per_minute,
                **{f'sorted_by_{r}': n for r, n in stats.sorted_by.items()},
                'give_ups': stats.give_ups, 'retries': stats.retries,
                'last_give_up': stats.last_give_up,
                'min_separation_m': guard.minimum, 'min_separation_time': guard.minimum_time,
                'estop': guard.stopped, 'estop_reason': guard.reason,
                'protective_stops': guard.protective, 'emergency_stops': guard.emergency,
                'mirror_error_max_m': mirror.error_max if stats.mode == 'mirrored' else None,
                'wall_seconds': took, 'sim_seconds': bridge.sim.time,
                'real_time_factor': bridge.sim.time / took, 'feed_interval': feed, 'seed': seed}
    finally:
        g.close()
