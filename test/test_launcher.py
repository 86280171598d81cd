"""scripts/launch_cell.py end to end: a clean run, Ctrl-C, a node that dies (real processes).

The launcher is run as a subprocess with the session's ROS_DOMAIN_ID (conftest.py). The
collaborative job itself (items sorted, throughput) is tested with the automation manager.
"""
import csv
import dataclasses
import importlib
import importlib.util
import json
import os
from pathlib import Path
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
LAUNCHER = ROOT / 'scripts' / 'launch_cell.py'
NODES = ('pybullet_bridge', 'left_planner', 'right_planner', 'replication_manager',
         'collision_monitor')
HAVE_AUTOMATION = importlib.util.find_spec('scara_collab.nodes.automation_manager') is not None
TIMEOUT = 180.0  # wall s for one launch; the graph starts in 10-25 s on a busy 2-core machine


class Launch:
    """``launch_cell.py`` as a subprocess; its stdout lines are collected by a thread."""

    def __init__(self, *args: str):
        """Start ``launch_cell.py args`` and a thread that collects its output lines."""
        env = dict(os.environ)  # the session's ROS_DOMAIN_ID (conftest.py)
        env['PYTHONUNBUFFERED'] = '1'
        self.proc = subprocess.Popen([sys.executable, str(LAUNCHER), *args], cwd=ROOT, env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True)
        self.lines: list = []
        self._queue: queue.Queue = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip('\n'))
            self._queue.put(line)

    def wait_for_line(self, pattern: str, timeout: float = TIMEOUT) -> str:
        """Return the first new line matching ``pattern`` (fails on timeout or exit)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                line = self._queue.get(timeout=0.2)
            except queue.Empty:
                if self.proc.poll() is not None and self._queue.empty():
                    break
                continue
            if re.search(pattern, line):
                return line
        pytest.fail(f'no line matching {pattern!r}; output:\n{self.output}')

    def wait(self, timeout: float = TIMEOUT) -> int:
        """Wait for the launcher to exit and its output to be read; return the exit code."""
        code = self.proc.wait(timeout=timeout)
        self._reader.join(timeout=10)
        return code

    @property
    def output(self) -> str:
        """Return the output so far, one string."""
        return '\n'.join(self.lines)

    def kill(self) -> None:
        """Kill the launcher if it still runs (its children follow it)."""
        if self.proc.poll() is None:  # the children follow (PR_SET_PDEATHSIG)
            self.proc.kill()
            self.proc.wait(timeout=30)


@pytest.fixture
def launch():
    """Yield ``start(*args)``, which launches; launchers still running are killed after."""
    made = []

    def start(*args):
        made.append(Launch(*args))
        return made[-1]

    yield start
    for la in made:
        la.kill()


def assert_complete_csv(path: Path, min_rows: int = 1) -> list:
    """Assert that a CSV file ends in a newline and has no ragged row; return its rows."""
    text = path.read_text()
    assert text.endswith('\n'), f'{path} ends in the middle of a line'
    rows = list(csv.reader(text.splitlines()))
    assert len(rows) - 1 >= min_rows, f'{path}: {len(rows) - 1} rows'
    assert all(len(r) == len(rows[0]) for r in rows), f'{path} has a ragged row'
    return rows


def assert_children_gone(out: Path, names=NODES) -> dict:
    """Assert that every process in ``pids.json`` is gone; return the pids."""
    pids = json.loads((out / 'pids.json').read_text())
    assert set(names) <= set(pids)
    for name, pid in pids.items():
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)  # reaped by the launcher: no process, not even a zombie
    return pids


def test_idle_run_writes_report_and_files(launch, tmp_path):
    """An idle run exits 0 with its report and every file.

    Summary, CSVs, plots, node logs, CPU costs, the MCAP recording and the GIF; with ``--tf``
    the state publisher is started and ready once it publishes ``/robot_description``.
    """
    out = tmp_path / 'idle'
    la = launch('--mode', 'idle', '--duration', '3', '--rtf', '1', '--output', str(out),
                '--record', '--animation', '--tf')
    assert la.wait() == 0, la.output
    text = la.output
    for stage in NODES + ('state_publisher',):
        assert re.search(rf'\[launch\] {stage} +ready in', text), stage
    assert 'scara_collab run: mode idle, finished (duration reached)' in text
    assert re.search(r'real-time factor \d+\.\dx', text)
    assert re.search(r'min arm sep\. +\d\.\d{3} m +\(OK: margin 0\.1 m\)', text)
    assert f'run folder     {out}' in text
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['mode'] == 'idle' and summary['interrupted'] is False
    assert summary['exit_reason'] == 'duration reached' and summary['exit_code'] == 0
    assert 3.0 - 1e-6 <= summary['sim_seconds'] < 3.5  # float sums of 1 ms steps
    assert summary['wall_seconds'] > 0 and summary['real_time_factor'] > 0
    assert summary['mirror_error_max_m'] is None and summary['margin_ok'] is True
    # 3 sim s at 100 Hz from sim t=0 (the graph starts paused, and pauses at the end); at 1x
    # the recorder (not in lockstep) keeps up with every state
    rows = assert_complete_csv(out / 'timeseries.csv', min_rows=295)
    assert rows[0][0] == 't' and rows[0][-2:] == ['mirror_error_m', 'arm_distance_m']
    assert assert_complete_csv(out / 'events.csv', min_rows=0)[0] == [
        'time', 'kind', 'item', 'class', 'robot', 'cause']
    for png in ('tool_paths.png', 'arm_distance.png', 'item_counts.png'):
        assert (out / png).read_bytes().startswith(b'\x89PNG'), png
    for node in NODES:
        assert (out / 'logs' / f'{node}.log').is_file(), node
    assert all(n['exit_code'] is not None for n in summary['nodes'].values())
    # the cost of each process over the run, CPU s per sim s, in the summary and the report
    cost = summary['cpu_per_sim_s']
    assert set(NODES) | {'launcher', 'total'} <= set(cost) <= set(NODES) | {
        'automation_manager', 'state_publisher', 'launcher', 'total'}
    assert all(v >= 0 for v in cost.values()) and cost['total'] > 0
    assert abs(cost['total'] - sum(v for k, v in cost.items() if k != 'total')) < 1e-3
    assert re.search(r'CPU per sim s +\d+\.\d{3} s +\(pybullet bridge \d', text)
    assert_children_gone(out)
    # --record: every node's topics in run.mcap; --animation: run.gif after the report
    topics = assert_complete_mcap(out, summary)
    assert {'/conveyor/items', '/collision_monitor/min_distance',
            '/replication_manager/mirror_error', '/emergency_stop'} <= topics
    assert re.search(r'\[animation\] .*run\.gif \(\d+ frames', text)
    assert (out / 'run.gif').read_bytes().startswith(b'GIF89a')


def assert_complete_mcap(out: Path, summary: dict) -> set:
    """``run.mcap`` has its footer, the summary's counts, /clock and /joint_states."""
    from scara_collab.records.mcap_log import iter_messages, Reading
    reading = Reading()
    counts: dict = {}
    for msg in iter_messages(out / 'run.mcap', reading=reading):
        counts[msg.topic] = counts.get(msg.topic, 0) + 1
    assert reading.complete, reading.error
    assert counts == summary['mcap']['topics'] and sum(counts.values()) > 0
    assert counts['/clock'] > 100 and counts['/joint_states'] > 100
    return set(counts)


@pytest.mark.skipif(not HAVE_AUTOMATION, reason='needs the automation manager')
def test_one_process_runs_every_node_on_one_executor(launch, tmp_path):
    """``--one-process``: the same stages, readiness and job, in one container process.

    With ``--feed-interval 0.9`` (faster than the arms can take, a capacity run): the flag
    reaches the bridge, which spawns an item every 0.9 sim s once the job runs.
    """
    out = tmp_path / 'one'
    la = launch('--mode', 'collaborative', '--duration', '20', '--rtf', '0', '--output',
                str(out), '--no-plots', '--one-process', '--feed-interval', '0.9')
    assert la.wait() == 0, la.output
    pid = re.search(r'\[launch\] cell: 6 nodes on one executor \(pid (\d+)\)', la.output)
    assert pid, la.output
    for stage in NODES + ('automation_manager',):  # each node's readiness, one process
        assert re.search(rf'\[launch\] {stage} +ready in .*\(pid {pid.group(1)}\)', la.output)
    pids = assert_children_gone(out, names=('cell',))
    assert list(pids) == ['cell'] and pids['cell'] == int(pid.group(1))
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['exit_reason'] == 'duration reached' and summary['margin_ok'] is True
    assert summary['sorted'] > 0 and summary['emergency_stops'] == []
    assert 20 <= summary['spawned'] <= 24, summary['spawned']  # 20 s / 0.9 s (1.8 s: 11)
    assert set(summary['cpu_per_sim_s']) == {'cell', 'launcher', 'total'}
    assert list(summary['nodes']) == ['cell']
    log = (out / 'logs' / 'cell.log').read_text()
    assert '[automation_manager]' in log and '[pybullet_bridge]' in log
    launch_json = json.loads((out / 'launch.json').read_text())
    cmd = launch_json['commands']['cell']
    assert cmd[1:3] == ['-m', 'scara_collab.run.container'] and cmd.count('--node') == 6


def test_the_container_reads_one_entry_and_its_arguments_per_node():
    """The container parses one entry and its arguments per ``--node``; every stage fits."""
    from scara_collab.run import container
    bridge = 'scara_collab.nodes.pybullet_bridge:main'
    left = 'scara_collab.nodes.planner:main_left'
    assert container.parse(['--node', bridge, '--ros-args', '-p', 'a:=1', '--node', left]) == [
        (bridge, ['--ros-args', '-p', 'a:=1']), (left, [])]
    for argv, why in (([], 'no node'), (['--ros-args'], 'expected --node'),
                      (['--node'], 'needs an entry'), (['--node', 'os:system'], 'unknown node')):
        with pytest.raises(ValueError, match=why):
            container.parse(argv)
    # every node of the graph has the executable and the class it names
    from scara_collab import graph
    for spec in graph.NODES:
        module, func = spec.entry.split(':')
        assert callable(getattr(importlib.import_module(module), func)), spec.entry
        module, cls = spec.component.split(':')
        assert isinstance(getattr(importlib.import_module(module), cls), type), spec.component
    from scara_collab.run import stages as plan
    from scara_collab.run.options import parse_options
    opts = parse_options(['--one-process'])
    assert opts.one_process
    stages = plan.stages(opts, True)
    assert [s.name for s in stages] == [n.name for n in graph.job_nodes()]
    cmd = plan.command(plan.one_process(stages), Path('/cfg'))
    assert container.parse(cmd[3:])[0] == (stages[0].entry, plan.node_args(stages[0],
                                                                           Path('/cfg')))


def test_sigint_mid_run_shuts_down_cleanly(launch, tmp_path):
    """Ctrl-C during the job (collaborative if the automation manager exists, else idle)."""
    mode = 'collaborative' if HAVE_AUTOMATION else 'idle'
    out = tmp_path / 'sigint'
    la = launch('--mode', mode, '--duration', '600', '--rtf', '1', '--output', str(out),
                '--no-plots', '--record')
    la.wait_for_line(r'\[launch\] (collaborative job started|graph idle) at sim t=')
    la.wait_for_line(r'^sim +[0-9.]+/600 s')  # mid-run: the first progress line (5 s wall)
    la.proc.send_signal(signal.SIGINT)
    assert la.wait(timeout=60) == 130, la.output
    assert 'interrupted (SIGINT)' in la.output
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['interrupted'] is True and summary['exit_reason'] == 'SIGINT'
    assert summary['mode'] == mode and summary['exit_code'] == 130
    if HAVE_AUTOMATION:  # the job was started, then stopped before the nodes
        assert re.search(r'\[launch\] automation_manager +ready in', la.output)
        assert 'job_stop' in summary, summary
    assert summary['joint_state_rows'] > 0
    rows = assert_complete_csv(out / 'timeseries.csv', min_rows=summary['joint_state_rows'])
    assert len(rows) - 1 == summary['joint_state_rows']
    assert_complete_csv(out / 'events.csv', min_rows=0)
    assert 'did not stop on SIGINT' not in la.output
    crashed = [p.name for p in (out / 'logs').glob('*.log')
               if 'Exception in' in p.read_text() or '[FATAL]' in p.read_text()]
    assert not crashed, crashed  # Ctrl-C ends each spin loop, not a callback
    assert_children_gone(out)
    assert_complete_mcap(out, summary)  # closed with its footer on the way out


@pytest.mark.skipif(not HAVE_AUTOMATION, reason='needs the automation manager')
def test_a_lost_start_answer_and_lost_gripper_answers_cost_a_retry(launch, tmp_path):
    """Fault injection through the launcher: lost start and gripper answers cost a retry.

    The first answer to /automation_manager/start and the first gripper answers are lost;
    the run still completes and its files agree.
    """
    out = tmp_path / 'faults'
    la = launch('--mode', 'collaborative', '--duration', '25', '--rtf', '0', '--output',
                str(out), '--no-plots', '--fault', 'drop:/automation_manager/start:1',
                '--fault', 'drop:/scara_left/gripper:1', '--fault',
                'drop:/scara_right/gripper:1')
    assert la.wait() == 0, la.output
    assert '/automation_manager/start: no answer in 5 s; asking again (2/4)' in la.output
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['exit_reason'] == 'duration reached'
    assert summary['sorted'] > 0 and summary['missed'] == 0
    log = (out / 'logs' / 'automation_manager.log').read_text()
    assert 'fault injection: drop /scara_left/gripper' in log  # lost, and the job went on
    # one source per figure: the top-level counts are the events' counts of the window
    assert all(summary[k] == summary['events'][k] for k in summary['events'])
    assert summary['min_separation_source'] == 'collision_monitor'
    events = assert_complete_csv(out / 'events.csv', min_rows=1)
    assert sum(1 for r in events[1:] if r[1] == 'sorted') >= summary['sorted']


def test_a_dead_node_ends_the_run_with_its_name(launch, tmp_path):
    """A node killed mid-run ends the run with exit 1, naming it and showing its log."""
    out = tmp_path / 'dead'
    la = launch('--mode', 'idle', '--duration', '600', '--rtf', '1', '--output', str(out),
                '--no-plots')
    la.wait_for_line(r'\[launch\] collision_monitor +ready in')
    la.wait_for_line(r'^sim +[0-9.]+/600 s')  # mid-run: the first progress line (5 s wall)
    pid = json.loads((out / 'pids.json').read_text())['collision_monitor']
    os.kill(pid, signal.SIGKILL)
    assert la.wait(timeout=60) == 1, la.output
    assert re.search(r'ERROR: node collision_monitor exited with code -9 \(SIGKILL\)', la.output)
    assert 'last lines of' in la.output and 'collision_monitor.log' in la.output
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['interrupted'] is True and summary['exit_code'] == 1
    assert 'collision_monitor' in summary['exit_reason']
    assert summary['nodes']['collision_monitor']['exit_code'] == -9
    assert_complete_csv(out / 'timeseries.csv', min_rows=1)
    assert_children_gone(out)


@pytest.mark.skipif(not HAVE_AUTOMATION, reason='needs the automation manager')
def test_a_stopped_collision_monitor_holds_the_arms_and_ends_the_run(launch, tmp_path):
    """SIGSTOP of the collision monitor mid-job: a node that hangs, rather than exits.

    Sim time waits for it (lockstep) for the bridge's lockstep_timeout (5 s wall); then the
    bridge holds both arms before it lets sim time go on without it, and no other node is
    dropped. The launcher names it after --silent-timeout (10 s) and ends the run: exit 1,
    the reason in summary.json, every node stopped cleanly (the monitor gets SIGCONT too).
    """
    out = tmp_path / 'stopped'
    la = launch('--mode', 'collaborative', '--duration', '600', '--rtf', '1', '--no-plots',
                '--output', str(out))
    la.wait_for_line(r'\[launch\] collaborative job started at sim t=')
    la.wait_for_line(r'^sim +[\d.]+/600 s', timeout=30)  # the first progress line: arms move
    pid = json.loads((out / 'pids.json').read_text())['collision_monitor']
    os.kill(pid, signal.SIGSTOP)
    t0 = time.monotonic()
    try:
        code = la.wait(timeout=60)
    finally:
        try:
            os.kill(pid, signal.SIGCONT)
        except ProcessLookupError:
            pass
    assert code == 1, la.output
    assert time.monotonic() - t0 < 40.0
    assert re.search(r'ERROR: node collision_monitor stopped answering \(silent 1\d\.\d s, '
                     r'last at sim t=[\d.]+ s\)', la.output), la.output
    assert 'did not stop on SIGINT' not in la.output
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['exit_code'] == 1 and summary['interrupted'] is True
    assert summary['exit_reason'].startswith('node collision_monitor stopped answering')
    assert summary['silent_node']['node'] == 'collision_monitor'
    assert {n: c['exit_code'] for n, c in summary['nodes'].items()} == {
        n: 0 for n in summary['nodes']}, 'every node lived until the launcher stopped it'
    assert 'job_stop' in summary
    # the bridge held both arms because the monitor was silent, and dropped nobody else
    bridge = (out / 'logs' / 'pybullet_bridge.log').read_text()
    held = {m[0]: float(m[1]) for m in re.findall(
        r'(scara_\w+): move \S+ held at t=([\d.]+) s: /collision_monitor silent for', bridge)}
    assert set(held) == {'scara_left', 'scara_right'}, bridge
    assert re.findall(r'lockstep: (\S+) kept sim time waiting', bridge) == ['/collision_monitor']
    # after the hold no arm moved: braking settles within 0.5 s, then nothing moves
    rows = assert_complete_csv(out / 'timeseries.csv', min_rows=summary['joint_state_rows'])
    assert_complete_csv(out / 'events.csv', min_rows=0)
    joints = [i for i, name in enumerate(rows[0]) if '_joint' in name]
    assert len(joints) == 6, rows[0]
    t_held = min(held.values())
    data = np.array([[float(r[0])] + [float(r[i]) for i in joints] for r in rows[1:]])
    after = data[data[:, 0] >= t_held + 0.5, 1:]
    assert len(after) >= 100, f'{len(after)} states after the hold at t={t_held:.2f} s'
    assert np.ptp(after, axis=0).max() < 1e-3, np.ptp(after, axis=0)
    # braking at the acceleration limits from at most the velocity limits: v^2 / 2a (+5 %)
    from scara_collab.core.model import load_cell
    arm = load_cell().leader
    reach = np.tile(arm.max_velocity ** 2 / (2 * arm.max_acceleration), 2) * 1.05
    stopping = data[data[:, 0] >= t_held, 1:]
    assert np.all(np.abs(stopping - stopping[0]).max(axis=0) <= reach), \
        'the arms braked, they did not go on'
    assert_children_gone(out)


def test_a_wall_clock_stamped_state_neither_ends_nor_enters_the_run(launch, tmp_path):
    """A rogue /joint_states stamped with wall time (1.79e9 s) is refused by every consumer.

    It once ended a run at once as 'duration reached' with a false sim time and 1.8e11
    'missing' states; now the run's time is the bridge's /clock and the run goes its length.
    """
    import rclpy
    from sensor_msgs.msg import JointState
    from scara_collab.nodes import conversions as conv

    out = tmp_path / 'rogue'
    la = launch('--mode', 'idle', '--duration', '25', '--rtf', '1', '--output', str(out),
                '--no-plots')
    la.wait_for_line(r'\[launch\] graph idle at sim t=')
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('rogue_state_publisher', context=ctx)
    try:
        pub = node.create_publisher(JointState, '/joint_states', 10)
        names = [n for a in ('scara_left', 'scara_right')
                 for n in (f'{a}_joint_1', f'{a}_joint_2', f'{a}_gripper_joint')]
        rogue = conv.joint_state(1.79e9, names, [0.0] * 6, [0.0] * 6, [0.0] * 6)
        logs = [out / 'logs' / f'{n}.log' for n in ('collision_monitor', 'left_planner')]
        end = time.monotonic() + 15.0  # until all have heard it (discovery can be slow):
        while time.monotonic() < end and not (  # the nodes, and the launcher's recorder
                all('stamp t=1790000000.000 s' in p.read_text() for p in logs)
                and 'stamp t=1790000000.000 s' in la.output):
            for _ in range(10):
                pub.publish(rogue)
                time.sleep(0.05)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert la.wait() == 0, la.output
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['exit_reason'] == 'duration reached'
    assert summary['sim_seconds'] == pytest.approx(25.0, abs=0.05)
    assert summary['joint_states_refused'] >= 1
    # gaps in the recorded states, not 1.8e11 from a wall-clock stamp: fewer than the run's
    # own 100 Hz states (a quiet machine misses none; at load 12-20, with two benchmarks
    # beside it, the recorder lost 700 and 2,959 of its ~3,500)
    assert summary['joint_states_missing'] < 100 * 60
    assert summary['emergency_stops'] == [] and summary['exit_code'] == 0
    rows = assert_complete_csv(out / 'timeseries.csv', min_rows=100)
    assert max(float(r[0]) for r in rows[1:]) < 100.0  # no wall-clock row
    for name in ('collision_monitor', 'left_planner'):
        log = (out / 'logs' / f'{name}.log').read_text()
        assert 'ignoring joint_states: stamp t=1790000000.000 s' in log, name


def test_the_lockstep_flag_sets_the_bridges_window():
    """``--lockstep on`` (default) keeps the bridge's window; ``off`` sets it to 0 (real time)."""
    from scara_collab.run.options import parse_options
    from scara_collab.run.stages import stages

    def bridge(argv):
        return next(s for s in stages(parse_options(argv), True)
                    if s.name == 'pybullet_bridge').params
    assert parse_options([]).lockstep is True
    assert 'lockstep_window' not in bridge([]) and 'lockstep_window' not in bridge(
        ['--lockstep', 'on'])
    assert parse_options(['--lockstep', 'off']).lockstep is False
    assert bridge(['--lockstep', 'off'])['lockstep_window'] == '0.0'
    assert bridge(['--lockstep', 'off'])['lockstep_expect']  # the guards are still expected
    with pytest.raises(SystemExit) as exc:
        parse_options(['--lockstep', 'maybe'])
    assert exc.value.code == 2


def test_a_person_starts_the_separation_monitor_and_sets_the_bridges_person():
    """``--person``: the bridge's scenario, seed and link; over topics the monitor and guards.

    Wired (the default) the bridge runs the monitor: no process of its own. Without
    ``--person`` the plan is today's: no monitor and none of those parameters. In a line,
    ``--person-cell K`` keeps the person (and the monitor) to cell K.
    """
    from scara_collab import graph
    from scara_collab.run.options import parse_options
    from scara_collab.run.stages import stages

    def plan(argv):
        return {s.name: s for s in stages(parse_options(argv), True)}
    plain = plan([])
    assert 'separation_monitor' not in plain
    assert not {'person', 'person_seed', 'lockstep_guards'} & set(
        plain['pybullet_bridge'].params)
    wired = plan(['--person', 'inlet', '--seed', '3'])
    assert list(wired) == [n.name for n in graph.job_nodes(people=True)]
    assert 'separation_monitor' not in wired
    bridge = wired['pybullet_bridge'].params
    assert (bridge['person'], bridge['person_seed']) == ('inlet', '3')
    assert (bridge['monitor_link'], bridge['lockstep_guards']) == ('wired',
                                                                   "['collision_monitor']")
    assert 'separation_monitor' not in bridge['lockstep_expect']
    person = plan(['--person', 'inlet', '--seed', '3', '--monitor-link', 'topics'])
    assert list(person) == [n.name for n in graph.job_nodes(people=True, monitor_link='topics')]
    bridge = person['pybullet_bridge'].params
    assert bridge['lockstep_guards'] == "['collision_monitor','separation_monitor']"
    assert 'separation_monitor' in bridge['lockstep_expect']
    assert person['separation_monitor'].configs == ('people',)
    line = ['--person', 'inlet', '--monitor-link', 'topics', '--cells', '2', '--person-cell',
            '1', '--line-cell']
    assert 'separation_monitor' not in plan(line + ['0'])
    assert plan(line + ['1'])['pybullet_bridge'].params['person'] == 'inlet'


@pytest.mark.skipif(not HAVE_AUTOMATION, reason='needs the automation manager')
def test_a_real_time_run_with_late_joint_states_ends_cleanly(launch, tmp_path):
    """``--lockstep off --rtf 1`` with every joint state 20 +- 10 ms late: a clean run.

    The bridge waits for nobody but watches the collision monitor, applies the latency to
    its ``/joint_states``, and the run ends at its duration (the states in flight when the
    bridge pauses there arrive), exit 0, ``lockstep off`` in the summary and the report.
    """
    out = tmp_path / 'realtime'
    la = launch('--mode', 'collaborative', '--duration', '8', '--rtf', '1', '--lockstep',
                'off', '--fault', 'latency:/joint_states:0.02:0.01', '--no-plots',
                '--output', str(out))
    assert la.wait() == 0, la.output
    assert re.search(r'real-time factor \d+\.\dx +lockstep off', la.output), la.output
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['lockstep'] == 'off' and summary['exit_code'] == 0
    assert summary['exit_reason'] == 'duration reached' and summary['margin_ok'] is True
    assert summary['sim_seconds'] == pytest.approx(8.0, abs=0.05)
    bridge = (out / 'logs' / 'pybullet_bridge.log').read_text()
    assert 'lockstep off: waiting for nobody; watching /collision_monitor' in bridge
    assert 'fault injection: latency /joint_states by 0.02 +- 0.01 s' in bridge
    assert 'lockstep: waited' not in bridge and 'holding both arms' not in bridge
    assert_children_gone(out)


def test_viewer_flag_adds_the_viewer_stage_last(monkeypatch):
    """``--viewer`` adds the viewer stage last; a busy or zero port is refused."""
    import socket
    from scara_collab.run import options
    from scara_collab.run.stages import stages
    names = [s.name for s in stages(options.parse_options([]), True)]
    assert 'cell_viewer' not in names
    with socket.socket() as probe:
        probe.bind(('', 0))
        port = probe.getsockname()[1]  # free once closed
    last = stages(options.parse_options(['--viewer', str(port)]), True)[-1]
    assert last.name == 'cell_viewer' and last.params['port'] == str(port)
    assert f'http://localhost:{port}' in last.ready
    monkeypatch.setattr(options, 'port_free', lambda port: True)
    assert options.parse_options(['--viewer']).viewer == options.VIEWER_PORT == 8080
    monkeypatch.undo()
    with socket.socket() as busy:  # a port in use is refused before anything starts
        busy.bind(('', 0))
        busy.listen()
        with pytest.raises(SystemExit) as exc:
            options.parse_options(['--viewer', str(busy.getsockname()[1])])
    assert exc.value.code == 2
    with pytest.raises(SystemExit):
        options.parse_options(['--viewer', '0'])


def test_the_lockstep_watch_names_only_a_node_that_leaves_a_clock_unanswered():
    """The lockstep watch names only a node that left a newer clock unanswered too long."""
    from scara_collab.nodes.lockstep_watch import LockstepWatch
    from scara_collab.run.options import parse_options
    watch = LockstepWatch(['/a', '/b'], limit=10.0)
    for name in ('/a', '/b', '/not_launched'):
        watch.answer(name, 1.0, 0.0)
    assert set(watch.reached) == {'/a', '/b'}
    assert watch.silent(1.0, 30.0) is None  # sim time stands still, all up to date: a stall
    watch.answer('/a', 5.0, 20.0)
    assert watch.silent(5.0, 9.0) is None   # behind, but not for long
    assert watch.silent(5.0, 25.0) == ('/b', 25.0, 1.0)
    assert watch.silent(1.0, 25.0) == ('/b', 25.0, 1.0), 'behind /a even if /clock was lost'
    watch.answer('/b', 0.5, 26.0)           # an old answer arriving late says nothing new
    assert watch.silent(5.0, 26.0) == ('/b', 26.0, 1.0)
    watch.answer('/b', float(2**31 - 1), 27.0)  # it left the lockstep
    assert watch.silent(5.0, 40.0) is None
    never = LockstepWatch(['/a', '/stopped_at_start'], limit=10.0)
    never.expect(100.0)                     # sim time starts: nobody has answered yet
    never.answer('/a', 0.02, 100.1)
    assert never.silent(0.02, 105.0) is None
    never.answer('/a', 0.04, 111.0)
    assert never.silent(0.04, 111.0) == ('/stopped_at_start', 11.0, 0.0)
    with pytest.raises(SystemExit):
        parse_options(['--silent-timeout', '0'])


def test_the_lockstep_watch_is_off_in_one_process():
    """With every node in one process the watch subscribes nothing (nobody can be behind).

    A hung node there stops the one thread, the bridge with it: the stall check ends the run.
    The answers would each cost the container a delivery to the launcher's process.
    """
    import rclpy
    from scara_collab.nodes import lockstep
    from scara_collab.run.liveness import Liveness
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        off = Liveness([], 10.0, ctx)
        assert off.silent(5.0, 100.0) is None and off._node is None
        off.close()
        on = Liveness(['collision_monitor'], 10.0, ctx)
        topics = on._node.get_subscriber_names_and_types_by_node('launch_cell_watch', '/')
        assert [t for t, _ in topics] == ['/' + lockstep.TOPIC]
        on.close()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_the_job_start_is_asked_again_while_the_manager_is_not_connected(tmp_path, monkeypatch):
    """Ask for the job's start again every 0.5 s while the manager refuses it as not connected.

    However slowly the launcher is scheduled: a deadline just beyond the pause fired when two
    CPU hogs descheduled it, and ended a run with an empty error.
    """
    from scara_collab.run import launcher as la
    from scara_collab.run.options import parse_options
    opts = parse_options(['--output', str(tmp_path), '--quiet'])
    console = la.Console(tmp_path / 'launch.log', True)
    run = la.Launcher(opts, tmp_path, console)
    try:
        connect_after = [3]  # the third request finds the manager connected
        asked = []

        def call(srv_type, name, request, timeout, what, **kwargs):
            if name == '/sim/resume':  # once the job has started
                return SimpleNamespace(success=True, message='resumed at sim t=0.000 s')
            asked.append(time.monotonic())
            ok = len(asked) >= connect_after[0]
            return SimpleNamespace(success=ok, message='started' if ok else
                                   'not connected yet: /scara_right/target (no subscriber)')

        slow = run.ros.check
        monkeypatch.setattr(run.ros, 'call', call)
        monkeypatch.setattr(run.ros, 'check', lambda: (time.sleep(0.7), slow()))  # descheduled
        monkeypatch.setattr(run.ros, 'set_bridge', lambda **values: None)
        monkeypatch.setattr(run.recorder, 'start_job', lambda: 0.0)
        run.start_job()
        assert len(asked) == 3 and run.job_started
        assert all(b - a >= 0.5 for a, b in zip(asked, asked[1:]))
        log = (tmp_path / 'launch.log').read_text()
        assert log.count('not connected yet: /scara_right/target (no subscriber); asking '
                         'again') == 2
        connect_after[0] = 10 ** 6  # never connected: ends with the reason, within the timeout
        asked.clear()
        run.opts = dataclasses.replace(run.opts, ready_timeout=1.0)
        with pytest.raises(la.RunEnd, match='refused to start for 1 s: not connected yet'):
            run.start_job()
    finally:
        run.close()
        console.close()


def test_the_namespace_flag_moves_every_stage_into_the_cell():
    """``--namespace /cell_1``: every node's command line puts it there, with the clock remap.

    Without it the commands are the root cell's (no ``-r``); a bad namespace is a usage error.
    """
    from scara_collab.run.options import parse_options
    from scara_collab.run.stages import command, one_process, stages
    config = Path('/cfg')
    plain = stages(parse_options([]), True)
    assert all('-r' not in command(s, config) for s in plain)
    moved = stages(parse_options(['--namespace', 'cell_1']), True)
    for stage in moved:
        cmd = command(stage, config)
        assert ['-r', '__ns:=/cell_1', '-r', '/clock:=/cell_1/clock'] == cmd[
            cmd.index('-r'):cmd.index('-r') + 4], stage.name
    assert 'service /cell_1/sim/resume' == moved[0].ready
    container = command(one_process(moved), config)
    assert container.count('__ns:=/cell_1') == len(moved)
    with pytest.raises(SystemExit):
        parse_options(['--namespace', 'cell 1'])
