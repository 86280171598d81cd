"""The sorting job in one process on one executor, unthrottled, lockstep gate on (DDS is async)."""
import time
from typing import Callable, Dict, Optional, Sequence

from scara_collab import graph
from scara_collab.core.config import load_config
from scara_collab.nodes.runner import InProcess


def default_feed() -> float:
    """Seconds between items of ``simulation.yaml`` (the feed every mode uses)."""
    return float(load_config('simulation')['feed_interval'])


def run_job(mode: str, duration: float, feed: Optional[float] = None,
            seed: Optional[int] = None, faults: Sequence[str] = (),
            during: Optional[Callable[[InProcess, Dict[str, object], float], None]] = None
            ) -> Dict[str, object]:
    """Run ``mode`` for ``duration`` sim s in one process; ``during(g, nodes, t)`` each turn.

    ``faults``: ``--fault`` entries, every node built with their hook
    (:func:`scara_collab.run.faults.hook`); a crash needs the launcher's supervisor.
    """
    wrap = None
    if faults:
        from scara_collab.run.faults import crashes, hook
        if crashes(faults):
            raise ValueError(f'crash faults need the launcher (a process to kill): {faults}')
        wrap = hook(faults)
    feed = default_feed() if feed is None else float(feed)
    seed = int(load_config('simulation')['item_seed'] if seed is None else seed)
    g = InProcess()
    params = graph.job_params(mode)  # as the launcher starts them
    params['pybullet_bridge'].update(real_time_factor=0.0, feed_interval=feed, item_seed=seed,
                                     lockstep_expect=graph.lockstep_expect(graph.job_nodes()))
    params['automation_manager']['auto_start'] = 'true'
    nodes = {}
    for spec in graph.job_nodes():
        nodes[spec.name] = g.add(spec.build(wrap, context=g.context, cli_args=graph.ros_args(
            spec.configs, params[spec.name])))
    bridge, job = nodes['pybullet_bridge'], nodes['automation_manager']
    wall = time.monotonic()
    try:
        while bridge.sim.time < duration:
            g.spin_once(timeout_sec=0.01)
            if during is not None:
                during(g, nodes, bridge.sim.time)
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
