"""The sorting job, measured: in one process (:func:`run_job`) or through the launcher.

:func:`run_job` builds the whole graph (bridge, both planners, replication manager, collision
monitor, automation manager) in ONE process on one executor, unthrottled: sim time cannot
run ahead of the planners and the automation manager while they compute, so the figures are
the job's own, free of the cross-process latency the launcher's separate processes add. The
bridge's lockstep gate stays on (its default window): even in one process, messages travel
through DDS asynchronously, and without the gate a loaded machine lets the bridge step on
before they arrive, which changes what the job does (seen as late moves and, once, a margin
breach). The wall time it takes gives the real-time factor of the graph in one process.

:func:`run_launcher` runs ``scara_collab.run.launcher`` (what ``scripts/launch_cell.py`` and
the demo run: one process per node) unthrottled and reads the run's ``summary.json``: the
real-time factor of the whole graph as separate processes.
"""
import json
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Callable, Dict, Optional, Sequence

from scara_collab import graph
from scara_collab.bench.util import Log
from scara_collab.core.config import load_config
from scara_collab.nodes.automation_manager import AutomationManager
from scara_collab.nodes.collision_monitor import CollisionMonitor
from scara_collab.nodes.replication_manager import ReplicationManager
from scara_collab.nodes.runner import InProcess

MODES = ('single', 'collaborative', 'mirrored')


def default_feed() -> float:
    """Seconds between items of ``simulation.yaml`` (the feed every mode uses)."""
    return float(load_config('simulation')['feed_interval'])


def run_job(mode: str, duration: float, feed: Optional[float] = None,
            seed: Optional[int] = None, log: Optional[Log] = None,
            report_every: float = 10.0, faults: Sequence[str] = (),
            during: Optional[Callable[[InProcess, Dict[str, object], float], None]] = None
            ) -> Dict[str, object]:
    """Run one mode for ``duration`` sim seconds in one process; return the job's stats.

    :param mode: ``'single'``, ``'collaborative'`` or ``'mirrored'``.
    :param feed: sim seconds between items (default: ``simulation.yaml``); mirrored mode
        feeds mirror pairs.
    :param seed: item feed seed (the bridge's ``item_seed``; default ``simulation.yaml``).
    :param report_every: sim seconds between progress lines.
    :param faults: fault injection entries for every node (:mod:`scara_collab.nodes.faults`).
    :param during: called as ``during(g, nodes, sim_time)`` after every turn of the executor
        (fault-injection tests: ``g`` the :class:`~scara_collab.nodes.runner.InProcess` graph,
        whose ``probe(name)`` adds a node of the caller's, ``nodes`` the graph's by name).
    :return: :func:`job_result` of the graph plus ``wall_seconds``, ``sim_seconds``,
        ``real_time_factor``, ``feed_interval``, ``seed``.
    """
    feed = default_feed() if feed is None else float(feed)
    seed = int(load_config('simulation')['item_seed'] if seed is None else seed)
    g = InProcess()  # the executables' executor ($SCARA_COLLAB_EXECUTOR)
    params = graph.job_params(mode)  # as the launcher starts them
    params['pybullet_bridge'].update(real_time_factor=0.0, feed_interval=feed, item_seed=seed,
                                     lockstep_expect=graph.lockstep_expect(graph.job_nodes()))
    params['automation_manager']['auto_start'] = 'true'
    built: Dict[str, object] = {}
    for spec in graph.job_nodes():
        own = dict(params[spec.name], **({'faults': list(faults)} if faults else {}))
        built[spec.name] = spec.build(context=g.context,
                                      cli_args=graph.ros_args(spec.configs, own))
    nodes = list(built.values())
    bridge, job = built['pybullet_bridge'], built['automation_manager']
    replication, monitor = built['replication_manager'], built['collision_monitor']
    for n in nodes:
        g.add(n)
    wall = time.monotonic()
    next_report = report_every
    try:
        while bridge.sim.time < duration:
            g.spin_once(timeout_sec=0.01)
            if during is not None:
                during(g, built, bridge.sim.time)
            if log and bridge.sim.time >= next_report:
                c = job.job.counts
                log(f'{mode} (seed {seed}): {bridge.sim.time:.0f}/{duration:.0f} sim s, sorted '
                    f'{c.get("sorted", 0)}, missed {c.get("missed", 0)}, '
                    f'{time.monotonic() - wall:.0f} s wall')
                next_report += report_every
        out = job_result(job, monitor, replication)
        took = time.monotonic() - wall
        out.update(wall_seconds=took, sim_seconds=bridge.sim.time,
                   real_time_factor=bridge.sim.time / took if took > 0 else None,
                   feed_interval=feed, seed=seed)
        return out
    finally:
        g.close()


def job_result(job: AutomationManager, monitor: CollisionMonitor,
               replication: ReplicationManager) -> Dict[str, object]:
    """Return the figures of an in-process job, each from its one source.

    Counts: the bridge's item events (as the automation manager heard them); minimum
    separation and emergency stop: the collision monitor; mirror error: the replication
    manager (in-step moves, mirrored mode only); give-ups and retries: the job.
    """
    stats = job.stats()
    mirror = replication.status()
    guard = monitor.status()
    return {'mode': stats.mode, **stats.counts,
            'items_per_minute': stats.items_per_minute,
            **{f'sorted_by_{r}': n for r, n in stats.sorted_by.items()},
            'give_ups': stats.give_ups, 'retries': stats.retries,
            'last_give_up': stats.last_give_up,
            'min_separation_m': guard.minimum, 'min_separation_time': guard.minimum_time,
            'estop': guard.stopped, 'estop_reason': guard.reason, 'stop_kind': guard.kind,
            'protective_stops': guard.protective, 'emergency_stops': guard.emergency,
            'mirror_error_max_m': mirror.error_max if stats.mode == 'mirrored' else None,
            'mirror_error_max_time': mirror.error_max_time,
            'mirror_in_step_moves': mirror.in_step_moves,
            'mirror_not_in_step': mirror.not_in_step}


def run_launcher(mode: str, duration: float, output: Path, rtf: float = 0.0,
                 seed: Optional[int] = None, timeout: float = 600.0,
                 extra: Sequence[str] = ()) -> Dict[str, object]:
    """Run the launcher (one process per node) unthrottled; return its ``summary.json``.

    :param output: the run folder (created by the launcher).
    :param rtf: the bridge's real-time factor (0 = as fast as the machine allows).
    :param timeout: wall seconds before the launcher is stopped.
    :param extra: more launcher flags (e.g. ``--feed-interval 1.0``, ``--fault ...``).
    :return: the summary plus ``exit_code`` and ``launcher_wall_seconds`` (start-up
        included); ``{'error': ...}`` if it did not produce a summary.
    """
    cmd = [sys.executable, '-c',
           'import sys; from scara_collab.run.launcher import main; sys.exit(main(sys.argv[1:]))',
           '--mode', mode, '--duration', f'{duration:g}', '--rtf', f'{rtf:g}', '--output',
           str(output), '--quiet', '--no-plots']
    if seed is not None:
        cmd += ['--seed', str(seed)]
    cmd += list(extra)
    start = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGINT)  # the launcher stops its nodes and writes its files
        try:
            stdout, stderr = proc.communicate(timeout=60.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            stdout, stderr = proc.communicate()
        return {'error': f'the launcher did not finish within {timeout:.0f} s',
                'exit_code': proc.returncode}
    took = time.monotonic() - start
    summary = Path(output) / 'summary.json'
    if not summary.is_file():
        tail = (stderr or stdout).strip().splitlines()[-5:]
        return {'error': f'no summary.json (exit code {proc.returncode}): ' + ' / '.join(tail),
                'exit_code': proc.returncode}
    out = json.loads(summary.read_text())
    out.update(exit_code=proc.returncode, launcher_wall_seconds=took)
    return out
