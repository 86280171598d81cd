"""The fault matrix: each case one launcher run, one fault injected, judged from its files."""
from contextlib import suppress
from dataclasses import dataclass
import os
from pathlib import Path
import signal
import tempfile
import time
from typing import Callable, Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
import numpy as np
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from benchmarks.launched import Launch, publish, stamp, stops, Summary, use_domain
from benchmarks.probe import Probe
from benchmarks.util import Log, table
from scara_collab.core.kinematics import fk, ik
from scara_collab.core.model import load_cell
from scara_collab.core.trajectory import joint_move
from scara_collab.nodes import conversions as conv

STATE_READERS = 5  # of joint_states: both planners, the monitor, the job, the recorder


def _states(t: float, position: float) -> JointState:
    names = [n for arm in load_cell().arms for n in arm.joint_names]
    return conv.joint_state(t, names, [position] * 6, [0.0] * 6, [0.0] * 6)


def nan_state_then_target(run: Launch) -> None:
    """Publish a NaN joint state (on sim time) five times, then a target for the left arm."""
    with Probe() as probe:
        pub = probe.publisher(JointState, 'joint_states', STATE_READERS)
        probe.wait_state()
        for _ in range(5):
            probe.spin(0.1)  # take the newest state, stamp a little ahead of it: only not finite
            pub.publish(_states(conv.to_sec(probe.state.header.stamp) + 0.1, float('nan')))
            probe.spin(0.05)
        target = probe.publisher(PointStamped, 'scara_left/target')
        target.publish(conv.make_point_stamped([2.4, -0.6, 0.5], 'world', 0.0))
        probe.spin(1.0)


def wall_clock_states(run: Launch) -> None:
    """Publish states stamped with wall time (1.79e9 s) for 3 s."""
    with Probe() as probe:
        pub = probe.publisher(JointState, 'joint_states', STATE_READERS)
        for _ in range(60):
            pub.publish(_states(1.79e9, 0.0))
            probe.spin(0.05)


def raw_crossing(run: Launch) -> None:
    """Park the left arm over the belt, then send the right arm a raw move through it."""
    cell = load_cell()
    left, right = cell.leader, cell.follower
    goal = np.array([1.8, -0.2, 0.4])  # over the belt, in both arms' reach
    with Probe() as probe:
        probe.publisher(PointStamped, 'scara_left/target').publish(
            conv.make_point_stamped(goal, 'world', 0.0))
        pub = probe.publisher(JointTrajectory, 'scara_right/joint_trajectory')
        end = time.monotonic() + 30.0
        while time.monotonic() < end:  # until the left arm is there
            probe.spin(0.1)
            ql = conv.joint_state_arrays(probe.wait_state(), left.joint_names)[0]
            if np.linalg.norm(fk(left, ql) - goal) < 0.005:
                break
        qr = conv.joint_state_arrays(probe.state, right.joint_names)[0]
        move = joint_move(right, qr, ik(right, goal, q_current=qr).unwrap())
        pub.publish(conv.trajectory_msg(right.joint_names, move.t, move.q, move.qd, move.qdd,
                                        frame_id='raw/crossing'))
        probe.spin(2.0)


def rogue_input(run: Launch) -> None:
    """Publish 200 bad targets in 2 s, a malformed trajectory and an oversized one."""
    joints = ['scara_left_joint_1', 'scara_left_joint_2', 'scara_left_gripper_joint']
    with Probe() as probe:
        target = probe.publisher(PointStamped, 'scara_left/target')
        traj = probe.publisher(JointTrajectory, 'scara_left/joint_trajectory')
        probe.wait_state()
        bad = [[float('nan'), -1.0, 0.4], [9.0, -2.0, 0.4], [2.0, -2.0, 0.4], [3.0, -1.0, 1.5]]
        for k in range(200):
            target.publish(conv.make_point_stamped(bad[k % len(bad)],
                                                   'map' if k % 7 == 0 else 'world', 0.0))
            probe.spin(0.01)
        traj.publish(conv.trajectory_msg([joints[0], 'nope', joints[2]], np.array([0.5]),
                                         np.zeros((1, 3))))
        heard = []
        probe.node.create_subscription(DiagnosticStatus, 'scara_left/execution_status',
                                       heard.append, 100)
        big = np.linspace(0.01, 1000.0, 100_001)
        ql = conv.joint_state_arrays(probe.state, joints)[0]
        traj.publish(conv.trajectory_msg(joints, big, np.tile(ql, (big.size, 1))))
        end = time.monotonic() + 60.0  # 100,001 points take a while to arrive: stay till then
        while time.monotonic() < end and not any('points' in m.message for m in heard):
            probe.spin(0.1)


def send(node: str, sig: int) -> Callable[[Launch], Optional[int]]:
    """Return an injection that sends ``sig`` to ``node`` (SIGSTOP: its pid, resumed after)."""
    def inject(run: Launch) -> Optional[int]:
        os.kill(pid := run.pid(node), sig)
        return pid if sig == signal.SIGSTOP else None
    return inject


def _died(s: Summary) -> List[str]:
    return [n for n, v in (s.get('nodes') or {}).items() if v.get('exit_code') not in (0, None)]


def _sep(s: Summary) -> float:
    return float('nan') if s.get('min_separation_m') is None else float(s['min_separation_m'])


def judge_nan(s: Summary, run: Launch) -> Tuple[bool, str]:
    """Pass if a NaN state made a protective stop that ended by itself, exit 0, none died."""
    on_it = [st for st in stops(s, 'protective')
             if 'unusable joint state' in str(st.get('cause'))]
    ok = (s.get('exit_code') == 0 and bool(on_it) and not any(st.get('standing') for st in on_it)
          and not stops(s, 'emergency') and not _died(s))
    return ok, (f'exit {s.get("exit_code")}, protective stops on it: {len(on_it)} ('
                + ', '.join(f'{float(st.get("lost") or 0):.2f} s' for st in on_it)
                + f'), died: {_died(s) or "none"}')


def judge_wall_clock(s: Summary, run: Launch) -> Tuple[bool, str]:
    """Pass if the run went its full length, states were refused and no e-stop was raised."""
    ok = s.get('exit_code') == 0 and s.get('exit_reason') == 'duration reached' \
        and (s.get('joint_states_refused') or 0) > 0 and not stops(s, 'emergency')
    return ok, (f'exit {s.get("exit_code")} ({s.get("exit_reason")}), sim '
                f'{s.get("sim_seconds")} s, {s.get("joint_states_refused")} states refused, '
                f'{len(stops(s, "emergency"))} e-stops')


def judge_crossing(s: Summary, run: Launch) -> Tuple[bool, str]:
    """Pass if the bridge refused the crossing at the door: exit 0, no stop, arms 0.1 m apart."""
    refused = 'would bring scara_right within' in run.log('pybullet_bridge')
    n_stops = [len(stops(s, kind)) for kind in ('protective', 'emergency')]
    ok = s.get('exit_code') == 0 and refused and _sep(s) >= 0.1 and not any(n_stops)
    return ok, (f'exit {s.get("exit_code")}, refused at the door: {refused}, stops: '
                f'{n_stops[0]} protective / {n_stops[1]} emergency, min separation '
                f'{_sep(s):.3f} m')


def judge_rogue(s: Summary, run: Launch) -> Tuple[bool, str]:
    """Pass if the bridge refused both bad trajectories, no node died and the arms stayed apart."""
    bridge = run.log('pybullet_bridge')
    refused = 'do not match this arm' in bridge and '100001 points; at most' in bridge
    ok = s.get('exit_code') == 0 and not _died(s) and refused and _sep(s) >= 0.1
    return ok, (f'exit {s.get("exit_code")}, died: {_died(s) or "none"}, bridge refused the '
                f'malformed and oversized trajectories: {refused}')


def judge_lost(s: Summary, run: Launch) -> Tuple[bool, str]:
    """Pass if the lost answers were retried: exit 0, items sorted and none missed."""
    ok = s.get('exit_code') == 0 and s.get('missed') == 0 and (s.get('sorted') or 0) > 0
    return ok, f'exit {s.get("exit_code")}, sorted {s.get("sorted")}, missed {s.get("missed")}'


def judge_saturated(s: Summary, run: Launch) -> Tuple[bool, str]:
    """Pass if the overfed run kept the arms 0.1 m apart without an e-stop."""
    ok = s.get('exit_code') == 0 and _sep(s) >= 0.1 and not stops(s, 'emergency')
    return ok, (f'exit {s.get("exit_code")}, sorted {s.get("sorted")} ({s.get("missed")} '
                f'missed: feed beyond capacity), min separation {_sep(s):.3f} m, '
                f'{len(stops(s, "emergency"))} e-stops')


def judge_sigstop(s: Summary, run: Launch) -> Tuple[bool, str]:
    """Pass if the run ended non-zero naming the frozen monitor while the bridge held."""
    reason = str(s.get('exit_reason') or '')
    ok = s.get('exit_code') not in (0, None) and 'collision_monitor' in reason \
        and 'holding' in run.log('pybullet_bridge')
    return ok, f'exit {s.get("exit_code")}: {reason[:80]}'


def judge_sigkill(s: Summary, run: Launch) -> Tuple[bool, str]:
    """Pass if the run ended with exit 1 naming the killed left planner."""
    reason = str(s.get('exit_reason') or '')
    return s.get('exit_code') == 1 and 'left_planner' in reason, \
        f'exit {s.get("exit_code")}: {reason[:80]}'


@dataclass
class Case:
    """One fault: what is expected, how long the run is, how it is judged and injected."""

    name: str
    expected: str
    duration: float
    judge: Callable[[Summary, Launch], Tuple[bool, str]]
    inject: Optional[Callable[[Launch], Optional[int]]] = None
    flags: Tuple[str, ...] = ()
    mode: str = 'collaborative'


CASES = (
    Case('NaN joint state, then a target', 'protective stop (fails closed) that ends by '
         'itself, no node dies, exit 0', 20.0, judge_nan, nan_state_then_target),
    Case('wall-clock stamped joint states', 'refused by every consumer; the run goes its '
         'length, exit 0', 20.0, judge_wall_clock, wall_clock_states),
    Case('raw trajectory through the other arm (no job)', 'refused at the door; no stop, the '
         'margin kept', 20.0, judge_crossing, raw_crossing, mode='idle'),
    Case('rogue publisher: 200 bad targets, malformed and 100,001-point trajectories',
         'all refused with reasons, no node dies, margin kept', 60.0, judge_rogue, rogue_input),
    Case('lost start and gripper answers', 'a retry each; the job completes, 0 missed', 30.0,
         judge_lost, flags=('--fault', 'drop:/automation_manager/start:1', '--fault',
                            'drop:/scara_left/gripper:2', '--fault',
                            'drop:/scara_right/gripper:2')),
    Case('saturated feed (an item every 0.8 s)', 'margin kept, no e-stop', 60.0,
         judge_saturated, flags=('--feed-interval', '0.8')),
    Case('collision monitor frozen (SIGSTOP)', 'the bridge holds the arms; the run ends '
         'non-zero naming the monitor', 120.0, judge_sigstop,
         send('collision_monitor', signal.SIGSTOP)),
    Case('left planner killed (SIGKILL)', 'the run ends with exit 1 naming it', 120.0,
         judge_sigkill, send('left_planner', signal.SIGKILL)),
)


def run_case(case: Case, out: Path, domain: int, log: Log) -> Dict:
    """Run one case in ROS domain ``domain``; return its row (a stopped pid is resumed after)."""
    use_domain(domain)
    run, frozen = Launch(case.mode, case.duration, out, 1.0, case.flags, quiet=False), None
    try:
        if not run.wait_for(r'(job started|graph idle) at sim t='):
            passed, observed = False, 'the job did not start: ' + ' / '.join(run.lines[-3:])
        else:
            try:
                frozen = case.inject(run) if case.inject is not None else None
                passed, observed = case.judge(run.finish(case.duration * 3 + 120), run)
            except Exception as exc:  # noqa: B902 - a failed injection is a failed case
                passed, observed = False, f'the injection failed: {type(exc).__name__}: {exc}'
    finally:
        if frozen is not None:
            with suppress(ProcessLookupError):  # unless the launcher has ended it
                os.kill(frozen, signal.SIGCONT)
        if run.proc.poll() is None:
            run.proc.kill()
            run.proc.wait()
    log(f'{case.name}: {"pass" if passed else "FAIL"} ({observed})')
    return {'case': case.name, 'expected': case.expected,
            'observed': observed.replace('|', '/'), 'pass': 'yes' if passed else '**no**'}


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the ``--cases`` (all: into the ``faults`` block); True if every one passed."""
    out = Path(tempfile.mkdtemp(prefix='scara_faults_'))
    start = time.monotonic()
    rows = [run_case(c, out / f'case_{k}', 50 + k, log) for k, c in enumerate(CASES, 1)
            if not args.cases or k in args.cases]
    passed = sum(r['pass'] == 'yes' for r in rows)
    text = stamp(command, start, f'{passed} of {len(rows)} cases pass.') + '\n\n' + table(rows)
    publish(text, None if args.cases else page, 'faults', 'Faults against the launcher', log, out)
    return passed == len(rows)
