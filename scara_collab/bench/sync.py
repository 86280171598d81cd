"""Section 4, synchronisation: mirrored moves through the ROS graph (mirror error, start lag).

The measurement is :func:`scara_collab.bench.sync.measure_moves` on
:func:`scara_collab.bench.sync.mirrored_targets`; this module is its summary row, its Markdown
(with the mirrored sorting job's in-step error, when section 7 ran it) and its figure.
"""
from dataclasses import dataclass
from pathlib import Path
import time
from typing import Dict, List, Optional, Sequence

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
import numpy as np
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from scara_collab import graph
from scara_collab.bench.throughput import mirrored_run
from scara_collab.bench.util import (canvas, Log, m, md_table, met, mm, num, plural, Progress,
                                     quote, Rows, save, Section, usable)
from scara_collab.core.kinematics import fk, IKError
from scara_collab.core.mirror import mirror_point
from scara_collab.core.model import load_cell
from scara_collab.core.planning import plan_path
from scara_collab.core.trajectory import segment_deviation
from scara_collab.nodes import conversions as conv, protocol as proto
from scara_collab.nodes.runner import InProcess


ROBOTS = ('scara_left', 'scara_right')
MOVE = (np.array([3.4, -1.15, 0.4]), np.array([2.2, -0.25, 0.4]))
"""A 1.5 m move towards the belt like the seeds' "rest position to the conveyor centre", but
ending 0.25 m short of the centre line: mirrored, the seeds' own move would put both tools on
the same belt point, and the right arm (correctly) waits for the left instead."""
ONSET = 1e-4  # m: a tool has started moving once it is this far from where it rested
SETTLE = 0.3  # s of sim time observed after the later arm's move ends


def mirrored_targets(n_moves: int, seed: int = 0) -> List[np.ndarray]:
    """Return ``n_moves + 1`` left-arm targets: :data:`MOVE`, then random straight lines.

    Random targets keep the left tool at ``y <= -0.25`` (its mirror at ``y >= 0.25``, so the
    two arms never need to wait for each other), ``0.5 m`` or more from the previous one,
    with a straight line from it that the planner accepts.
    """
    arm = load_cell().leader
    targets = [MOVE[0], MOVE[1]]
    rng = np.random.default_rng(seed)
    q = plan_path(arm, plan_path(arm, np.array([0.0, np.pi / 2, 0.0]), MOVE[0],
                                 mode='line_or_joint').q[-1], MOVE[1]).q[-1]
    while len(targets) < n_moves + 1:
        p = np.array([rng.uniform(1.6, 3.4), rng.uniform(-1.3, -0.25), rng.uniform(0.3, 0.5)])
        if np.linalg.norm(p - targets[-1]) < 0.5:
            continue
        try:
            q = plan_path(arm, q, p, mode='line').q[-1]
        except IKError:
            continue
        targets.append(p)
    return targets[:n_moves + 1]


def measure_moves(mode: str = 'line', targets: Optional[Sequence[np.ndarray]] = None,
                  timeout: float = 120.0, log: Optional[Log] = None) -> Dict[str, object]:
    """Send ``targets`` one after another to ``/collab/target`` through a fresh graph.

    :param mode: the planners' ``mode`` (``'line'`` or ``'joint'``).
    :param targets: left-arm targets in world; the first only positions the arms (default
        :data:`MOVE`: one measured 1.5 m move).
    :param timeout: wall seconds to wait for any one step.
    :return: ``{'mode', 'moves': [per move dict], 'physics_step_s', 'state_period_s',
        summary keys (worst over the moves)}``.
    """
    targets = [np.asarray(p, float) for p in (targets if targets is not None else MOVE)]
    g = InProcess('single')
    own = {'pybullet_bridge': {'real_time_factor': 0.0, 'feed_interval': 0.0},
           'left_planner': {'mode': mode}, 'right_planner': {'mode': mode}}
    nodes = [spec.build(context=g.context,
                        cli_args=graph.ros_args(spec.configs, own.get(spec.name)))
             for spec in map(graph.node, ('pybullet_bridge', 'left_planner', 'right_planner',
                                          'replication_manager'))]
    for n in nodes:
        g.add(n)
    bridge, left_pl, right_pl, _ = nodes
    probe = g.probe('bench')
    states: List[JointState] = []
    trajs: Dict[str, JointTrajectory] = {}
    starts: Dict[str, float] = {}
    probe.create_subscription(JointState, '/joint_states', states.append, 1000)
    for r in ROBOTS:
        probe.create_subscription(JointTrajectory, f'/{r}/joint_trajectory',
                                  lambda m, r=r: trajs.__setitem__(r, m), 10)

        def on_status(msg: DiagnosticStatus, r=r) -> None:
            st = proto.ExecutionStatus.from_msg(msg)
            if st.state == 'accepted':
                starts[r] = st.start
        probe.create_subscription(DiagnosticStatus, f'/{r}/execution_status', on_status, 100)

    def spin_until(pred, what: str) -> None:
        end = time.monotonic() + timeout
        while not pred() and time.monotonic() < end:
            g.spin_once(timeout_sec=0.005)
        if not pred():
            raise RuntimeError(f'mirrored moves: timed out waiting for {what}')

    try:
        cell = bridge.cell
        left, right = cell.leader, cell.follower
        spin_until(lambda: left_pl.q is not None and right_pl.q is not None
                   and conv.now(left_pl) > 0.1, 'the planners to see the arms')
        pub = probe.create_publisher(PointStamped, '/collab/target', 10)
        spin_until(lambda: pub.get_subscription_count() > 0, 'the replication manager')
        moves = []
        for i, target in enumerate(targets):
            trajs.clear()
            starts.clear()
            t_send = bridge.sim.time
            pub.publish(conv.make_point_stamped(target))
            spin_until(lambda: len(trajs) == 2, 'both trajectories')
            end = max(conv.to_sec(m.header.stamp) + conv.to_sec(m.points[-1].time_from_start)
                      for m in trajs.values())
            spin_until(lambda: bridge.sim.time > end + SETTLE, 'the end of the move')
            if log:
                log(f'mirrored move {i}/{len(targets) - 1} ({mode}) done at sim '
                    f't={bridge.sim.time:.1f} s')
            if i == 0:
                continue
            stamps = {r: conv.to_sec(m.header.stamp) for r, m in trajs.items()}
            moves.append(_move_metrics(left, right, states, t_send, targets[i - 1], target,
                                       stamps, dict(starts)))
        period = float(np.median(np.diff([conv.to_sec(m.header.stamp) for m in states[-50:]])))
        out: Dict[str, object] = {'mode': mode, 'moves': moves, 'physics_step_s': bridge.dt,
                                  'state_period_s': period}
        for key in ('mirror_error_max_m', 'start_stamp_difference_s',
                    'bridge_start_difference_s', 'start_lag_measured_s',
                    'leader_line_deviation_m', 'leader_end_error_m'):
            vals = [m[key] for m in moves if m[key] is not None]
            out[key] = max(vals) if vals else None
        out['mirror_error_mean_m'] = float(np.mean([m['mirror_error_mean_m'] for m in moves])) \
            if moves else None
        return out
    finally:
        g.close()


def _move_metrics(left, right, states: List[JointState], t_send: float, start: np.ndarray,
                  goal: np.ndarray, stamps: Dict[str, float],
                  starts: Dict[str, float]) -> Dict[str, object]:
    """Mirror error, start lags and line deviation of one move, from the joint states."""
    t, pl, pr = [], [], []
    for msg in states:
        ts = conv.to_sec(msg.header.stamp)
        if ts >= t_send:
            t.append(ts)
            pl.append(conv.joint_state_arrays(msg, left.joint_names)[0])
            pr.append(conv.joint_state_arrays(msg, right.joint_names)[0])
    t = np.array(t)
    pl, pr = fk(left, np.array(pl)), fk(right, np.array(pr))
    err = np.linalg.norm(pr - mirror_point(left, right, pl), axis=1)

    def onset(p):
        moved = np.linalg.norm(p - p[0], axis=1) > ONSET
        return float(t[np.argmax(moved)]) if moved.any() else None

    on_l, on_r = onset(pl), onset(pr)
    bridge_diff = abs(starts[ROBOTS[0]] - starts[ROBOTS[1]]) \
        if all(r in starts for r in ROBOTS) else None
    return {
        'start': start.tolist(), 'goal': goal.tolist(),
        'length_m': float(np.linalg.norm(goal - start)),
        'duration_s': float(t[-1] - t[0]),
        'mirror_error_max_m': float(err.max()),
        'mirror_error_mean_m': float(err.mean()),
        'start_stamp_difference_s': abs(stamps[ROBOTS[0]] - stamps[ROBOTS[1]]),
        'bridge_start_difference_s': bridge_diff,
        'start_lag_measured_s': None if on_l is None or on_r is None else abs(on_l - on_r),
        'leader_line_deviation_m': float(segment_deviation(pl, start, goal).max()),
        'leader_end_error_m': float(np.linalg.norm(pl[-1] - goal)),
        'series': {'t': t - t[0], 'mirror_error': err},
    }


TARGETS = {
    'mirror_error': 1e-3,          # m
}
"""The SPEC's targets (``../shared/SPEC.md`` §5), as numbers."""


@dataclass(frozen=True)
class Sizes:
    """How many mirrored moves go through the graph."""

    mirrored_moves: int = 6


def measure(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    """Send the mirrored straight-line moves through the graph and measure them."""
    targets = mirrored_targets(sizes.mirrored_moves)
    return measure_moves('line', targets, log=progress.note)


def summary(g: dict) -> Rows:
    """Return the summary row: worst mirror error and start lag."""
    lag = g['bridge_start_difference_s']
    if lag is None:  # the bridge did not report its starts: the stamps are what we have
        lag = g['start_stamp_difference_s']
    return [('mirror error / start lag (mirrored moves through the graph)', '4 mm / 15 ms',
             f'max {mm(g["mirror_error_max_m"])} / {num((lag or 0) * 1e3, 2, "ms")} '
             f'({plural(len(g["moves"]), "move")})', '≤ 1 mm / ≤ 1 physics step',
             met(g['mirror_error_max_m'] <= TARGETS['mirror_error']
                 and lag is not None and lag <= g['physics_step_s'] + 1e-9))]


def markdown(g: dict, results: dict) -> str:
    """Return the section's text: the claims, every move's mirror error and start lags."""
    rows = []
    for i, mv in enumerate(g['moves'], 1):
        rows.append((i, f'{tuple(round(v, 2) for v in mv["start"])} → '
                        f'{tuple(round(v, 2) for v in mv["goal"])}',
                     m(mv['length_m']), mm(mv['mirror_error_max_m'], 2),
                     mm(mv['mirror_error_mean_m'], 2),
                     num(mv['start_stamp_difference_s'] * 1e3, 2, 'ms'),
                     num(mv['bridge_start_difference_s'] * 1e3, 2, 'ms')
                     if mv['bridge_start_difference_s'] is not None else 'n/a',
                     num(mv['start_lag_measured_s'] * 1e3, 2, 'ms')
                     if mv['start_lag_measured_s'] is not None else 'n/a',
                     mm(mv['leader_line_deviation_m'])))
    rows.append(('', "*seeds' claim*", '', '', '4 mm (average)', '15 ms (max lag)',
                 '15 ms (max lag)', '15 ms (max lag)', '< 1 mm (planned)'))
    t = results.get('throughput')
    job = ''
    mj = mirrored_run(t) if usable(t) else None
    if mj:
        job = (f'Over the mirrored sorting job ({mj["sim_seconds"]:.0f} sim s, seed {mj["seed"]},'
               f" in one process; section 7) the automation manager's largest in-step mirror "
               f'error was {mm(mj["mirror_error_max_m"])} (target ≤ 1 mm: '
               f'{met((mj["mirror_error_max_m"] or 0) <= TARGETS["mirror_error"])}).')
    return '\n\n'.join([
        quote('mirror_error', 'lag'),
        f'{plural(len(g["moves"]), "mirrored straight-line move")} through the ROS graph '
        '(bridge, both '
        'planners and the replication manager in one process on sim time, unthrottled): each '
        'target goes to `/collab/target`, the left arm moves there, the right arm to the '
        "mirror image, with one start stamp. Mirror error: the right tool's distance from the "
        'mirror of the left tool, over the move, from `/joint_states` '
        f'(every {num(g["state_period_s"] * 1e3, 2, "ms")}). Start lag three ways: the start '
        'stamps of the two trajectories, the starts the bridge reports having executed '
        f'(physics step {num(g["physics_step_s"] * 1e3, 2, "ms")}), and the measured onsets '
        '(first state 0.1 mm from rest; resolution one state period).',
        md_table(('move', 'left target (m)', 'length', 'mirror error max', 'mean',
                  'start stamps Δ', 'bridge starts Δ', 'onsets Δ', 'leader off the line'),
                 rows, 'rlrrrrrrr'),
        f"Seeds' claim: 4 mm average mirror error, 15 ms maximum lag. Measured: worst mirror "
        f'error {mm(g["mirror_error_max_m"])}, mean {mm(g["mirror_error_mean_m"])}; worst '
        f'start difference at the bridge '
        f'{num((g["bridge_start_difference_s"] or 0) * 1e3, 2, "ms")}.'
        + (" The right arm's measured states are the exact mirror image of the left arm's "
           '(error 0 to the last bit).' if g['mirror_error_max_m'] == 0.0 else '')
        + (f' {job}' if job else '')])


def figure(data: dict, path: Path) -> None:
    """Mirror error over each mirrored move."""
    fig, ax = canvas(8.0, 3.2)
    offset = 0.0
    for mv in data['moves']:
        s = mv['series']
        ax.semilogy(offset + np.asarray(s['t']), np.maximum(s['mirror_error'], 1e-9) * 1e3,
                    color='tab:purple', lw=1.0)
        offset += float(s['t'][-1]) + 0.2
    ax.axhline(1.0, color='k', lw=0.8, ls=':')
    ax.axhline(4.0, color='tab:red', lw=0.8, ls='--')
    ax.text(0.0, 4.6, "seeds' claim: 4 mm average", fontsize=7, color='tab:red')
    ax.set_ylim(1e-6, 20)
    ax.set_xlabel('sim time over the moves, one after another (s)')
    ax.set_ylabel('mirror error (mm)')
    ax.set_title(f'{len(data["moves"])} mirrored moves through the ROS graph '
                 '(1e-6 mm floor)', fontsize=10)
    save(fig, path)


SECTION = Section(
    key='sync', title='synchronisation: mirrored moves through the graph',
    heading='Synchronisation: mirror error and start lag', measure=measure, markdown=markdown,
    summary=summary, figure=figure, figure_alt='mirror error over the moves', full=Sizes(),
    smoke=Sizes(mirrored_moves=1))
