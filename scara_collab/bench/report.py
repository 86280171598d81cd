"""``RESULTS.md`` from the benchmark's results: every table with the seeds' claim beside it.

Every number printed here comes from the results dict of one run
(:func:`scara_collab.bench.suite.run`); the only constants are the seeds' claims
(:mod:`scara_collab.bench.claims`, quoted with their section) and the SPEC targets below.
"""
import math
from typing import Dict, List, Optional, Sequence

import numpy as np

from scara_collab.bench.claims import CLAIMS, PAYLOAD_CLAIMS
from scara_collab.bench.figures import CONTROLLERS
from scara_collab.bench.solvers import display
from scara_collab.bench.util import fmt_seconds, md_table, spread

TARGETS = {
    'ik_latency': 5e-6,            # s, one target
    'ik_rate': 1e6,                # targets/s, vectorised
    'line_planned': 1e-6,          # m
    'line_executed': 1e-3,         # m
    'mirror_error': 1e-3,          # m
    'pair_ratio': 1.9,             # pair / single items per minute
    'pair_rate': 30.0,             # items/min
    'margin': 0.10,                # m, arm-to-arm, never broken
    'rtf': 5.0,                    # whole graph, unthrottled, in one process
    'rtf_processes': 3.5,          # whole graph, unthrottled, one process per node (issue 15)
    'topp': 1.01,                  # line time / TOPP-RA, worst case (issue 15)
}
"""The SPEC's targets (``../shared/SPEC.md`` §5), as numbers."""

TITLES = {
    'paths': '1. Path deviation: straight line vs joint interpolation',
    'solvers': '2. Solver speed, against reference implementations',
    'payload': '3. Payload response: PID vs computed torque',
    'sync': '4. Synchronisation: mirror error and start lag',
    'singularity': '5. Singularity: pseudo-inverse vs damped least squares',
    'foresight': '6. Collision foresight and margins',
    'throughput': '7. Throughput and real-time factor',
}


# --- formatting ------------------------------------------------------------------------------
def _ok(x) -> bool:
    return x is not None and not (isinstance(x, float) and math.isnan(x))


def mm(x: Optional[float], digits: int = 3) -> str:
    """Format metres as millimetres (``'n/a'`` for None)."""
    return f'{x * 1e3:.{digits}g} mm' if _ok(x) else 'n/a'


def m(x: Optional[float], digits: int = 3) -> str:
    """Format metres."""
    return f'{x:.{digits}g} m' if _ok(x) else 'n/a'


def num(x: Optional[float], digits: int = 3, unit: str = '') -> str:
    """Format a number with ``digits`` significant digits and an optional unit."""
    if not _ok(x):
        return 'n/a'
    return f'{x:.{digits}g}' + (f' {unit}' if unit else '')


def plural(n: int, word: str) -> str:
    """Return ``'1 move'``, ``'3 moves'``."""
    return f'{n} {word}' + ('' if n == 1 else 's')


def met(flag: Optional[bool]) -> str:
    """Format a target check."""
    return '' if flag is None else ('**met**' if flag else '**not met**')


def quote(*keys: str) -> str:
    """Blockquote the seeds' claims ``keys`` with their sources."""
    return '\n'.join(f'> {CLAIMS[k].quote} — *{CLAIMS[k].source}*\n>' for k in keys).rstrip('>\n')


def _usable(data) -> bool:
    return isinstance(data, dict) and 'error' not in data and not data.get('skipped')


def _unusable(data) -> str:
    if isinstance(data, dict) and data.get('skipped'):
        return '*Not run in this invocation (`--only`).*'
    err = data.get('error') if isinstance(data, dict) else 'no data'
    return f'**This section failed:** `{err}`'


def _figure(results: dict, key: str, alt: str) -> str:
    name = (results.get('figures') or {}).get(key, '')
    if name.endswith('.png'):
        return f'![{alt}](figures/{name})'
    return f'*(figure not drawn: {name or "no data"})*'


# --- derived figures, shared by the summary and the sections ---------------------------------
def _solver_row(data: dict, prefix: str) -> Optional[dict]:
    for r in data['rows']:
        if r['what'].startswith(prefix):
            return r
    return None


def _jobs(data: dict, mode: str) -> List[dict]:
    return [r for r in data['runs'] if r['mode'] == mode]


def _mirrored_run(data: dict) -> Optional[dict]:
    runs = _jobs(data, 'mirrored')
    return runs[0] if runs else data.get('mirrored')


def _launcher(data: dict, name: str) -> Optional[dict]:
    run = (data.get('launchers') or {}).get(name)
    return run if run and 'error' not in run else None


def _cost(run: dict) -> Optional[float]:
    return (run.get('cpu_per_sim_s') or {}).get('total')


def _pair_ratio(data: dict) -> Dict[str, float]:
    """Pair / single items per minute, per seed run with both modes."""
    single = {r['seed']: r['items_per_minute'] for r in _jobs(data, 'single')}
    pair = {r['seed']: r['items_per_minute'] for r in _jobs(data, 'collaborative')}
    return spread(pair[s] / single[s] for s in single if s in pair and single[s] > 0)


def _worst_inner(data: dict) -> Optional[dict]:
    for case in data['cases']:
        if 'inner' in case['name'] and 'radial' in case['name']:
            return case
    return None


def _foresight_stats(data: dict) -> Dict[str, object]:
    pairs = data['pairs']
    conflicts = [p for p in pairs if p['conflict']]
    executed = [p['executed_min_m'] for p in pairs if p['executed_min_m'] is not None]
    planned = [p['planned_min_m'] for p in pairs if p['planned_min_m'] is not None]
    return {
        'n': len(pairs), 'conflicts': len(conflicts),
        'touch': sum(p['impact_s'] is not None for p in conflicts),
        'foresight': spread(p['foresight_s'] for p in conflicts),
        'foresight_median': float(np.median([p['foresight_s'] for p in conflicts]))
        if conflicts else None,
        'impact': spread(p['impact_s'] for p in conflicts),
        'impact_median': float(np.median([p['impact_s'] for p in conflicts
                                          if p['impact_s'] is not None]))
        if any(p['impact_s'] is not None for p in conflicts) else None,
        'outcomes': {k: sum(p['outcome'] == k for p in pairs)
                     for k in ('clear', 'delayed', 'waits')},
        'conflict_outcomes': {k: sum(p['outcome'] == k for p in conflicts)
                              for k in ('clear', 'delayed', 'waits')},
        'delay': spread(p['delay_s'] for p in conflicts if p['delay_s'] is not None),
        'delay_median': float(np.median([p['delay_s'] for p in conflicts
                                         if p['delay_s'] is not None]))
        if any(p['delay_s'] is not None for p in conflicts) else None,
        'decision': spread(p['decision_s'] for p in pairs),
        'decision_median': float(np.median([p['decision_s'] for p in pairs])) if pairs else None,
        'unresolved': spread(p['unresolved_min_m'] for p in conflicts),
        'planned': spread(planned),
        'executed': spread(executed),
        'planned_breaches': sum(v < data['margin'] for v in planned),
        'executed_breaches': sum(v < data['margin'] for v in executed),
    }


# --- the summary -----------------------------------------------------------------------------
def headline(results: dict) -> List[Sequence[str]]:
    """Return the summary rows: what, seeds' claim, measured here, SPEC target, met."""
    rows: List[Sequence[str]] = []
    s = results.get('solvers')
    if _usable(s):
        one = _solver_row(s, 'IK, one target')
        vec = next(r for r in s['rows'] if r['what'].startswith('IK,') and r['kind'] == 'rate')
        rows.append(('IK latency', CLAIMS['ik_latency'].figure,
                     f'{fmt_seconds(one["ours"])} one target; '
                     f'{vec["ours"] / 1e6:.3g} M targets/s vectorised',
                     '≤ 5 µs; ≥ 10⁶/s',
                     met(one['ours'] <= TARGETS['ik_latency']
                         and vec['ours'] >= TARGETS['ik_rate'])))
    p = results.get('paths')
    if _usable(p):
        lp, le = p['planned']['line']['max_deviation'], p['executed']['line']['max_deviation']
        rows.append(("straight line, seeds' 1.5 m move: deviation planned / executed",
                     CLAIMS['line_deviation'].figure, f'{m(lp, 2)} / {mm(le)}',
                     '≤ 1e-6 m / ≤ 1 mm',
                     met(lp <= TARGETS['line_planned'] and le <= TARGETS['line_executed'])))
        rows.append(('joint interpolation, same move: deviation planned / executed',
                     CLAIMS['joint_deviation'].figure,
                     f'{m(p["planned"]["joint"]["max_deviation"])} / '
                     f'{m(p["executed"]["joint"]["max_deviation"])}', 'reported', ''))
        saved = 1 - p['planned']['line']['path_length'] / p['planned']['joint']['path_length']
        rows.append(('path length saved by the line', CLAIMS['path_length'].figure,
                     f'{saved * 100:.1f} %', '', ''))
    g = results.get('sync')
    if _usable(g):
        lag = g['bridge_start_difference_s']
        if lag is None:  # the bridge did not report its starts: the stamps are what we have
            lag = g['start_stamp_difference_s']
        rows.append(('mirror error / start lag (mirrored moves through the graph)',
                     '4 mm / 15 ms',
                     f'max {mm(g["mirror_error_max_m"])} / {num((lag or 0) * 1e3, 2, "ms")} '
                     f'({plural(len(g["moves"]), "move")})', '≤ 1 mm / ≤ 1 physics step',
                     met(g['mirror_error_max_m'] <= TARGETS['mirror_error']
                         and lag is not None and lag <= g['physics_step_s'] + 1e-9)))
    pay = results.get('payload')
    if _usable(pay):
        ct = [r for r in pay['rows'] if r['mode'] == 'computed_torque']
        pid = [r for r in pay['rows'] if r['mode'] == 'pid']
        settle = [r['settling'] for r in ct]
        rows.append(('payload 0 / 1 / 2.5 kg: settling to 1 mm', '0.45 / 0.72 / 1.15 s',
                     'computed torque: ' + ' / '.join(
                         num(x, 2, 's') if x is not None else 'never' for x in settle)
                     + "; PID (seeds' gains): " + ' / '.join(
                         num(r['settling'], 2, 's') if r['settling'] is not None
                         else f'not in {r["window"]:g} s' for r in pid), '', ''))
    sg = results.get('singularity')
    if _usable(sg):
        case = _worst_inner(sg)
        if case:
            rows.append(("peak joint speed into the inner singularity (seeds' loop)",
                         CLAIMS['singularity'].figure,
                         f'pseudo-inverse {case["pinv"]["peak_speed"]:.3g} rad/s, DLS '
                         f'{case["dls"]["peak_speed"]:.3g} rad/s; planner ≤ '
                         f'{sg["planner"]["peak_speed"]:.3g} rad/s', '≤ 2 rad/s',
                         met(case['dls']['peak_speed'] <= sg['velocity_limit'] + 1e-9)))
    f = results.get('foresight')
    if _usable(f):
        st = _foresight_stats(f)
        rows.append(('collision foresight (crossing pairs)', CLAIMS['foresight'].figure,
                     f'{st["conflicts"]} conflicts in {st["n"]} pairs, all found at the decision,'
                     f' {num(st["foresight"]["min"], 2, "s")} (min) before the margin would '
                     f'break; {st["executed_breaches"]} breaches in {st["executed"]["n"]} '
                     'executed', 'resolved at planning time; zero breaches',
                     met(st['planned_breaches'] == 0 and st['executed_breaches'] == 0)))
    t = results.get('throughput')
    if _usable(t):
        single = spread(r['items_per_minute'] for r in _jobs(t, 'single'))
        pair_runs = _jobs(t, 'collaborative')
        pair = spread(r['items_per_minute'] for r in pair_runs)
        ratio = _pair_ratio(t)
        margin = min((r['min_separation_m'] for r in pair_runs
                      if r.get('min_separation_m') is not None), default=None)
        stops = sum(1 for r in pair_runs if r.get('estop'))
        ok = None
        if pair['n'] and ratio['n']:
            ok = (ratio['mean'] >= TARGETS['pair_ratio'] and stops == 0
                  and margin is not None and margin >= TARGETS['margin'])
        rows.append((f'capacity single / pair (items/min, an item every '
                     f'{t["feed_interval"]:g} s)', CLAIMS['throughput'].figure,
                     f'{num(single["mean"])} ± {num(single["std"], 2)} / {num(pair["mean"])} ± '
                     f'{num(pair["std"], 2)}; pair = {num(ratio["mean"])}× single; min '
                     f'separation {m(margin)}, {stops} e-stops',
                     'pair ≥ 1.9× single, margin kept', met(ok)))
        rated = t.get('rated')
        if rated:
            rows.append((f'rated feed, collaborative, {rated["sim_seconds"]:.0f} sim s',
                         '22 items/min', f'{num(rated["items_per_minute"])} items/min, '
                         f'{rated["missed"]} missed, {rated["give_ups"]} give-ups',
                         '≥ 30/min, none missed', met(rated['items_per_minute'] >=
                                                      TARGETS['pair_rate']
                                                      and rated['missed'] == 0)))
        topp = t.get('topp') or {}
        if 'worst' in topp:
            rows.append(('line time / TOPP-RA (random lines)', '',
                         f'median {topp["median"]:.4f}, worst {topp["worst"]:.4f} '
                         f'({topp["n"]} lines)', '≤ 1.01 (issue 15)',
                         met(topp['worst'] <= TARGETS['topp'])))
        one, sep = _launcher(t, 'one_process'), _launcher(t, 'processes')
        if one or sep:
            parts = []
            if one:
                parts.append(f'in one process {num(one["real_time_factor"], 2)}× '
                             f'({num(_cost(one), 2)} CPU s per sim s)')
            if sep:
                parts.append(f'as separate processes {num(sep["real_time_factor"], 2)}× '
                             f'({num(_cost(sep), 2)} CPU s per sim s)')
            ok = None
            if one and sep:
                ok = (one['real_time_factor'] >= TARGETS['rtf']
                      and sep['real_time_factor'] >= TARGETS['rtf_processes'])
            rows.append(('real-time factor, whole graph, unthrottled (launcher)',
                         CLAIMS['rtf'].figure, '; '.join(parts),
                         '≥ 5× one process, ≥ 3.5× processes', met(ok)))
    return rows


# --- the sections ----------------------------------------------------------------------------
def _paths(p: dict, results: dict) -> str:
    pl, ex = p['planned'], p['executed']

    def speeds(x):
        return f'{x["peak_speed"][0]:.2f}, {x["peak_speed"][1]:.2f}'

    rows = [
        ('largest distance from the straight segment', m(pl['joint']['max_deviation']),
         m(ex['joint']['max_deviation']), m(pl['line']['max_deviation'], 2),
         mm(ex['line']['max_deviation']), 'joint 0.385 m; line < 0.001 m'),
        ('tool path length', m(pl['joint']['path_length'], 4), m(ex['joint']['path_length'], 4),
         m(pl['line']['path_length'], 4), m(ex['line']['path_length'], 4),
         'line 14 % shorter'),
        ('duration: planned (time-optimal, same joint limits) / executed (until the tool '
         'stays within 1 mm of the goal)',
         num(pl['joint']['duration'], 3, 's'), num(ex['joint']['duration'], 3, 's'),
         num(pl['line']['duration'], 3, 's'), num(ex['line']['duration'], 3, 's'), ''),
        ('peak joint speed θ1, θ2 (rad/s)', speeds(pl['joint']), speeds(ex['joint']),
         speeds(pl['line']), speeds(ex['line']), ''),
        ('RMS tool jerk, 100 Hz samples (m/s³)', num(pl['joint']['rms_jerk']),
         num(ex['joint']['rms_jerk']), num(pl['line']['rms_jerk']), num(ex['line']['rms_jerk']),
         'joint high, line low'),
        ('end error', '', mm(ex['joint']['end_error']), '', mm(ex['line']['end_error']), ''),
        ('largest tool error against the plan', '', mm(ex['joint']['max_tracking_error']), '',
         mm(ex['line']['max_tracking_error']), ''),
        ('planning time', fmt_seconds(p['plan_time_s']['joint']), '',
         fmt_seconds(p['plan_time_s']['line']), '', ''),
    ]
    saved = 1 - pl['line']['path_length'] / pl['joint']['path_length']
    start, goal = p['start'], p['goal']
    return '\n\n'.join([
        quote('joint_deviation', 'line_deviation', 'path_length'),
        f'The seeds\' "1.5m move from the rest position to the conveyor center", taken as '
        f'{tuple(start)} → {tuple(goal)} m in world for `{p["arm"]}` ({p["length_m"]:.3f} m), '
        'planned by the motion core both ways, each time-optimal under the same joint '
        'velocity and acceleration limits, then executed in the PyBullet cell '
        f'(`{p["control_mode"]}`, 1 kHz physics) and measured from the joint states at 100 Hz.',
        md_table(('metric', 'joint interp., planned', 'joint interp., executed',
                  'straight line, planned', 'straight line, executed', "seeds' claim"), rows),
        f'The straight line is {saved * 100:.1f} % shorter than the joint-interpolated path '
        f'(seeds: 14 %); joint interpolation bows {m(pl["joint"]["max_deviation"])} off the '
        'line (seeds: 0.385 m). RMS jerk is of the tool position, third difference of the '
        '100 Hz samples (the seeds give no number, only "high" and "low").',
        _figure(results, 'paths', 'tool paths seen from above and their deviation')])


def _solvers(s: dict, results: dict) -> str:
    rows = []
    for r in s['rows']:
        d = display(r)
        claim = CLAIMS['ik_latency'].figure if r['what'] == 'IK, one target' else ''
        target = f'{r["target"]} {met(r["met"])}'.strip() if r['target'] else ''
        rows.append((r['what'], d['ours'], d['reference'], d['ratio'], r['note'], target,
                     claim))
    meta = results['meta']
    sizes = s['sizes']
    ik_one = _solver_row(s, 'IK, one target')
    return '\n\n'.join([
        quote('ik_latency', 'solver_latency'),
        f'On {meta["cpu"]} ({meta["cores"]} cores), Python {meta["python"]}, numpy '
        f'{meta["numpy"]}; references in the same process on the same inputs. One call: '
        f'median of {sizes["repeats"]} loops of {sizes["n_calls"]} calls; N at once: median '
        f'of {sizes["repeats"]} calls on {sizes["n_vectorised"]} random states (arm-to-arm: '
        f'{sizes["n_state_pairs"]}). "ours vs reference" = how many times faster ours is '
        '(< 1: slower). The references without a batch API are called once per item. The '
        'seeds claim only an IK latency; the other rows have no claimed figure.',
        md_table(('what', 'ours', 'reference (same run)', 'ours vs reference',
                  'agreement / note', 'SPEC target', "seeds' claim"), rows),
        f'One IK call takes {ik_one["ours"] / 0.32e-3 * 100:.2g} % of the seeds\' claimed '
        f'0.32 ms and {ik_one["ours"] / 0.01 * 100:.2g} % of the 10 ms control period. '
        "Called one state at a time, numpy's per-call overhead makes the core slower than "
        "Pinocchio's and coal's C++; on N states at once it is faster than calling them in "
        'a loop. The machine may have been shared during the run (load at the start: '
        f'{num(meta["load_1min"], 2)}): absolute figures are noisy, ratios less so.',
        _figure(results, 'solvers', 'speed-up over the references')])


def _payload(pay: dict, results: dict) -> str:
    rows = []
    for r in pay['rows']:
        claim = PAYLOAD_CLAIMS.get(float(r['payload']))
        settle = num(r['settling'], 3, 's') if r['settling'] is not None \
            else f'not within {r["window"]:g} s'
        rows.append((f'{r["payload"]:g} kg', CONTROLLERS[r['mode']], settle,
                     ', '.join(f'{v:.1f}' for v in r['peak']), f'{r["overshoot"]:.2f} %',
                     mm(r['tool_err']), mm(r['final']),
                     f'{claim[0]} s, {claim[1]} N·m, {claim[2]} %' if claim else ''))
    start, goal = pay['line']
    dur = pay['rows'][0]['duration'] if pay['rows'] else float('nan')
    return '\n\n'.join([
        quote('payload'),
        f'A planned straight line {tuple(start)} → {tuple(goal)} m (`{pay["arm"]}`, 1.5 m, '
        f'{dur:.2f} s time-optimal) executed in the PyBullet cell with the payload hung on the '
        "tool (a fixed constraint, so physics feels it), by the seeds' PID gains (planar "
        '15/0.5/2, quill 10/0.1/1) and by computed torque (the Lagrangian model as '
        'feed-forward). Settling: time after the trajectory ends until the tool stays within '
        f'{mm(pay["settle_tolerance_m"], 2)} of the goal. Overshoot: furthest tool travel past '
        'the goal along the line, % of the line. Peak effort is the largest commanded joint '
        'effort over the run (N·m, N·m, N).',
        md_table(('payload', 'controller', 'settling to 1 mm', 'peak effort θ1, θ2, quill',
                  'overshoot', 'max tool error vs plan', 'final error', "seeds' claim "
                  '(settle, peak torque, overshoot)'), rows, 'llrlrrrl'),
        _payload_summary(pay),
        _figure(results, 'payload', 'distance to the goal over time, per payload')])


def _payload_summary(pay: dict) -> str:
    text = []
    for mode, name in (('pid', "With the seeds' PID gains"),
                       ('computed_torque', 'With computed torque')):
        runs = [r for r in pay['rows'] if r['mode'] == mode]
        if not runs:
            continue
        settled = [r for r in runs if r['settling'] is not None]
        text.append(
            f'{name}, {len(settled)} of {len(runs)} runs settle within their window; the '
            f'largest tool error against the plan is {mm(max(r["tool_err"] for r in runs))} '
            f'and the largest quill error {mm(max(r["joint_err"][2] for r in runs))}.')
    return ' '.join(text)


def _sync(g: dict, results: dict) -> str:
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
    if _usable(t) and _mirrored_run(t):
        mj = _mirrored_run(t)
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
        + (f' {job}' if job else ''),
        _figure(results, 'sync', 'mirror error over the moves')])


def _singularity(sg: dict, results: dict) -> str:
    rows = []
    for c in sg['cases']:
        rows.append((c['name'], num(c['pinv']['min_manipulability'], 2, 'm²'),
                     f'{c["pinv"]["elbow_deg_at_min"]:.1f}°',
                     num(c['pinv']['peak_speed'], 3, 'rad/s'),
                     num(c['dls']['peak_speed'], 3, 'rad/s'),
                     mm(c['pinv']['max_tool_error'], 2), mm(c['dls']['max_tool_error'], 2),
                     CLAIMS['singularity'].figure if 'inner' in c['name'] else ''))
    pl = sg['planner']
    rows.append((f'planner: time-optimal line {tuple(pl["line"][0])} → {tuple(pl["line"][1])} '
                 '(the closest inner graze the ±150° limit allows)',
                 num(pl['min_manipulability'], 2, 'm²'), f'{pl["max_elbow_deg"]:.1f}°', '',
                 f'{pl["peak_speed"]:.3g} rad/s ('
                 f'{"DLS engaged" if pl["damping_engaged"] else "no damping needed"})', '',
                 f'{m(pl["max_deviation"], 2)} (planned)', ''))
    return '\n\n'.join([
        quote('singularity', 'unreachable', 'peak_velocity'),
        f'Straight lines (base frame of `scara_left`) at {sg["speed"]} m/s through the seeds\' '
        f'differential-kinematics loop at {1 / sg["dt"]:.0f} Hz '
        f'(`core.trajectory.resolved_rate`, position feedback {sg["gain"]:g}/s), once with the '
        'plain pseudo-inverse, once with DLS (damping up to '
        f'{sg["dls_max_damping"]} m below manipulability {sg["dls_threshold"]} m²). The inner '
        "cases need elbow angles beyond the arm's ±150° limit: they test the solver where the "
        'seeds put their claim, not a move the cell can make.',
        md_table(('path', 'smallest manipulability', 'elbow angle there', 'peak speed, '
                  'pseudo-inverse', 'peak speed, DLS', 'off the line, pseudo-inverse',
                  'off the line, DLS', "seeds' claim"), rows, 'lrrrrrrl'),
        _singularity_summary(sg),
        f'The line into the inner circle, given to the planner: *{sg["planner_radial_inner"]}*. '
        f'IK on the seeds\' target 3.0 m from the shoulder axis: *{sg["far_target_result"]}* '
        '(seeds: "rejected the command immediately").',
        _figure(results, 'singularity', 'joint speed along the study paths')])


def _singularity_summary(sg: dict) -> str:
    lim = sg['velocity_limit']
    over = [c['name'] for c in sg['cases'] if c['pinv']['peak_speed'] > lim]
    under = [c['name'] for c in sg['cases'] if c['pinv']['peak_speed'] <= lim]
    dls_over = [c['name'] for c in sg['cases'] if c['dls']['peak_speed'] > lim]
    text = []
    if under:
        text.append('Undamped, the joint speeds stay under the limit on: ' + '; '.join(under)
                    + ' (a tangent graze asks for no radial motion where it is closest).')
    if over:
        text.append('The pseudo-inverse exceeds the limit on: ' + '; '.join(over) + '.')
    text.append('DLS keeps every case under the limit.' if not dls_over else
                'DLS still exceeds the limit on: ' + '; '.join(dls_over) + '.')
    text.append('DLS pays with the distance off the line shown. The planner does not rely on '
                'damping for the 2 rad/s limit: it times each path so that no joint exceeds it '
                f'(peak {sg["planner"]["peak_speed"]:.3g} rad/s on its line).')
    return ' '.join(text)


def _foresight(f: dict, results: dict) -> str:
    st = _foresight_stats(f)
    co, oc = st['conflict_outcomes'], st['outcomes']
    rows = [
        ('crossing pairs drawn', f'{st["n"]}', ''),
        (f'conflicts (closer than the {m(f["margin"], 2)} margin if started together)',
         f'{st["conflicts"]} ({st["touch"]} would touch)', ''),
        ('when a conflict is found', 'at the decision, before either arm moves (t = 0)',
         CLAIMS['foresight'].figure),
        ('decision → margin would break: min / median / max',
         f'{num(st["foresight"]["min"], 3, "s")} / {num(st["foresight_median"], 3, "s")} / '
         f'{num(st["foresight"]["max"], 3, "s")}', '200 ms before impact'),
        ('decision → capsules would touch: min / median',
         f'{num(st["impact"]["min"], 3, "s")} / {num(st["impact_median"], 3, "s")}', ''),
        ('motion starts after the decision (start lead)', num(f['lead'], 3, 's'), ''),
        ('conflicts resolved by delaying the right arm / the left arm never delayed / '
         'unresolvable (the follower waits)',
         f'{co["delayed"]} / {co["clear"]} / {co["waits"]}', ''),
        ('all pairs: clear / delayed (incl. the planning buffer) / waits',
         f'{oc["clear"]} / {oc["delayed"]} / {oc["waits"]}', ''),
        ('delay applied to conflicting pairs: median / max',
         f'{num(st["delay_median"], 3, "s")} / {num(st["delay"]["max"], 3, "s")}', ''),
        ('scheduling wall time per pair: median / max',
         f'{fmt_seconds(st["decision_median"])} / {fmt_seconds(st["decision"]["max"])}', ''),
        ('conflicting pairs started together: smallest distance, min / mean',
         f'{m(st["unresolved"]["min"])} / {m(st["unresolved"]["mean"])}', ''),
        ('every pair as scheduled (planned): smallest distance, min / mean',
         f'{m(st["planned"]["min"])} / {m(st["planned"]["mean"])}; breaches '
         f'{st["planned_breaches"]}', 'near-zero risk'),
        (f'conflicting pairs executed in physics with their delays ({st["executed"]["n"]}): '
         'smallest measured distance, min / mean',
         f'{m(st["executed"]["min"])} / {m(st["executed"]["mean"])}; breaches '
         f'{st["executed_breaches"]}', ''),
    ]
    t = results.get('throughput')
    if _usable(t):
        seps = [r['min_separation_m'] for r in t['runs'] if r.get('mode') != 'single'
                and r.get('min_separation_m') is not None]
        if t.get('mirrored') and t['mirrored'].get('min_separation_m') is not None:
            seps.append(t['mirrored']['min_separation_m'])
        if seps:
            rows.append((f'sorting jobs with both arms ({plural(len(seps), "run")}, section 7): '
                         'smallest '
                         'separation, min / mean',
                         f'{m(min(seps))} / {m(float(np.mean(seps)))}; breaches '
                         f'{sum(s < f["margin"] for s in seps)}', ''))
    return '\n\n'.join([
        quote('foresight', 'collision_risk'),
        f'{st["n"]} random pairs of crossing moves (seed {f["seed"]}): each arm between two '
        'random reachable points of its side and the shared zone, the tool paths crossing in '
        'plan view, the resting poses compatible (so a delay can always resolve a conflict). '
        f'Both moves are decided at t = 0 and asked to start at t = {f["lead"]:g} s, planned '
        'and scheduled by the motion core exactly as the planner nodes do (left has priority; '
        'the right arm waits the smallest delay, 10 ms resolution, that keeps '
        f'{m(f["planning_margin"], 2)}: the margin plus the planners\' buffer). Distances are '
        f'predicted on a {f["grid_s"] * 1e3:g} ms grid. The first {f["n_execute"]} conflicting '
        'pairs are then executed in physics with their delays and the separation is measured '
        'from the simulated joint states.',
        md_table(('what', 'measured', "seeds' claim"), rows),
        "The seeds' 200 ms is a detection before impact while moving; here a conflict is "
        'found when the moves are planned, before either starts, and resolved then (the '
        f'follower starts later). Margin breaches: {st["planned_breaches"]} planned, '
        f'{st["executed_breaches"]} executed in physics. The collision monitor (runtime '
        'e-stop below the margin) is the safety net behind this.',
        _figure(results, 'foresight', 'foresight and separation histograms')])


def _run_row(r: dict) -> tuple:
    return (r['mode'], str(r['seed']), num(r['items_per_minute']), str(r['sorted']),
            str(r['missed']), str(r.get('dropped', 0) + r.get('wrong_bin', 0)),
            str(r.get('give_ups', 'n/a')), m(r.get('min_separation_m'))
            if r['mode'] != 'single' else 'n/a', 'yes' if r.get('estop') else 'no',
            f'{num(r["real_time_factor"], 2)}×')


def _cost_cells(run: Optional[dict], names: Sequence[str]) -> List[str]:
    cost = (run or {}).get('cpu_per_sim_s') or {}
    return [num(cost[k], 2) if k in cost else '' for k in names]


def _throughput(t: dict, results: dict) -> str:
    claims = {'single': '12 items/min', 'collaborative': '22 items/min'}
    rows = []
    for mode in t['modes']:
        runs = _jobs(t, mode)
        ipm = spread(r['items_per_minute'] for r in runs)
        sep = [r['min_separation_m'] for r in runs if r.get('min_separation_m') is not None]
        rows.append((mode, ', '.join(str(r['seed']) for r in runs),
                     f'{num(ipm["mean"])} ± {num(ipm["std"], 2)} ({num(ipm["min"])}–'
                     f'{num(ipm["max"])})',
                     ', '.join(str(r['sorted']) for r in runs),
                     ', '.join(str(r.get('give_ups', 'n/a')) for r in runs),
                     ', '.join(str(r.get('dropped', 0) + r.get('wrong_bin', 0)) for r in runs),
                     m(min(sep)) if sep and mode != 'single' else 'n/a',
                     str(sum(1 for r in runs if r.get('estop'))),
                     num(float(np.mean([r['real_time_factor'] for r in runs])), 2) + '×',
                     claims.get(mode, '')))
    ratio = _pair_ratio(t)
    cyc = t.get('cycle') or {}
    single = spread(r['items_per_minute'] for r in _jobs(t, 'single'))
    parts = [
        quote('throughput', 'rtf'),
        '**Capacity** is items sorted per minute with the feed faster than the arms can take: '
        f'an item every {t["feed_interval"]:g} s ({60 / t["feed_interval"]:.0f}/min, random '
        'lateral offset; mirrored mode: a mirror pair every '
        f'{2 * t["feed_interval"]:g} s). The whole graph (bridge, planners, replication '
        'manager, collision monitor, automation manager) runs in one process on one executor, '
        "unthrottled on sim time with the bridge's lockstep gate on: "
        f'{plural(len(t["seeds"]), "item-feed seed")} ({", ".join(map(str, t["seeds"]))}) × '
        f'{", ".join(t["modes"])}, {t["duration"]:g} sim s each. Items/min = items sorted per '
        'sim minute of the job. Give-ups: moves the job abandoned (an item that got away, a '
        'grasp that failed); dropped + wrong bin: items that left the belt some other way.',
        md_table(('mode', 'seeds', 'items/min mean ± sd (min–max)', 'sorted', 'give-ups',
                  'dropped + wrong bin', 'min separation', 'e-stops', 'real-time factor',
                  "seeds' claim"), rows, 'llrrrrrrrl'),
    ]
    if ratio['n']:
        parts.append(f'Pair / single: **{num(ratio["mean"])}** ± {num(ratio["std"], 2)} over '
                     f'{ratio["n"]} seeds (seeds: 22 / 12 = 1.83; target ≥ 1.9 with the margin '
                     'kept and no emergency stop).')
    if cyc:
        frac = single['mean'] / cyc['items_per_min_median'] if single['n'] else None
        parts.append(
            f"**Cycle bound** (a single arm, the planners' own moves from above a bin down to "
            f'an item on the belt and back, {cyc["cases"]} pick points × both bins, no grasp '
            f'or release time): best {cyc["best_s"]:.2f} s ({cyc["items_per_min_best"]:.1f} '
            f'items/min, at {", ".join(f"{v:.2f}" for v in cyc["best_pick"])} m), median '
            f'{cyc["median_s"]:.2f} s ({cyc["items_per_min_median"]:.1f}/min).'
            + (f' The single arm sorts {num(single["mean"])}/min at capacity: {frac:.0%} of the '
               "median-cycle bound; the rest is the job's per-cycle time (grasp and release "
               'calls, the decision lead, waiting for an item to come into reach).'
               if frac else ''))
    reps = t.get('repeats') or []
    if len(reps) > 1:
        parts.append(
            f'**Repeatability**: the same run (collaborative, seed {reps[0]["seed"]}, same '
            f'flags) {len(reps)} times: sorted {", ".join(str(r["sorted"]) for r in reps)}; '
            f'give-ups {", ".join(str(r.get("give_ups")) for r in reps)}; min separation '
            f'{", ".join(m(r.get("min_separation_m")) for r in reps)}. '
            + ('Identical.' if len({(r['sorted'], r['missed']) for r in reps}) == 1 else
               'Not identical: the lockstep gate lets the bridge run up to one window (20 ms) '
               'ahead of a node, so how long a callback takes on this machine can move a '
               'decision by a tick, and the runs part from there.'))
    rated = t.get('rated')
    if rated:
        parts.append(
            f'**Rated feed** (an item every {t["rated_feed"]:g} s, collaborative, seed '
            f'{rated["seed"]}, {rated["sim_seconds"]:.0f} sim s, one process): '
            f'{rated["sorted"]} sorted, {rated["missed"]} missed, '
            f'{rated.get("dropped", 0) + rated.get("wrong_bin", 0)} dropped or wrong bin, '
            f'{rated["give_ups"]} give-ups, {num(rated["items_per_minute"])} items/min, min '
            f'separation {m(rated["min_separation_m"])}.')
    topp = t.get('topp') or {}
    if 'worst' in topp:
        parts.append(f'**Line timing against TOPP-RA** (toppra, same path and limits, '
                     f'{topp["n"]} random lines): line time / TOPP-RA median '
                     f'{topp["median"]:.4f}, best {topp["best"]:.4f}, worst '
                     f'{topp["worst"]:.4f} (target ≤ 1.01: {met(topp["worst"] <= 1.01)}).')
    elif topp:
        parts.append(f'Line timing against TOPP-RA: not measured ({topp.get("error")}).')
    speed = (results.get('payload') or {}).get('speed') if _usable(results.get('payload')) \
        else None
    rtf_rows = []
    if speed:
        for r in speed['rows']:
            rtf_rows.append((f'simulator alone, {r["mode"].replace("_", " ")}, {r["items"]} '
                             'items, both arms moving', f'{r["rtf"]:.3g}×',
                             f'{r["steps_per_s"]:,.0f} steps/s'))
    one = spread(r['real_time_factor'] for r in t['runs'])
    if one['n']:
        rtf_rows.append(('whole graph in one process, in-process (the capacity runs above)',
                         f'{num(one["mean"], 3)}× ({num(one["min"], 3)}–{num(one["max"], 3)})',
                         ''))
    launchers = t.get('launchers') or {}
    for name, what in (('one_process', 'the launcher, --one-process'),
                       ('processes', 'the launcher, one process per node')):
        lr = launchers.get(name)
        if not lr:
            continue
        if 'error' in lr:
            rtf_rows.append((f'whole graph, {what}', 'failed', lr['error']))
            continue
        rtf_rows.append((
            f'whole graph, {what} (collaborative, rated feed, {lr["sim_seconds"]:.0f} sim s)',
            f'{num(lr["real_time_factor"], 3)}×',
            f'{num(_cost(lr), 3)} CPU s per sim s; sorted {lr.get("sorted")}, missed '
            f'{lr.get("missed")}, min separation {m(lr.get("min_separation_m"))}, exit code '
            f'{lr.get("exit_code")}'))
    if rtf_rows:
        head = ''
        if speed:
            head = (f'Simulator alone: {speed["physics_rate"]:.0f} Hz physics, servo '
                    f'{speed["servo_rate"]:.0f} Hz, {speed["solver_iterations"]} solver '
                    f'iterations, one core, median of {plural(speed["repeat"], "run")} of '
                    f'{speed["seconds"]:g} s. ')
        parts.append(head + 'Real-time factor = sim seconds per wall second (seeds: ≈ 1.0; '
                     'target ≥ 5× in one process, ≥ 3.5× as separate processes, issue 15). '
                     'On a shared machine these are lower bounds.')
        parts.append(md_table(('configuration', 'real-time factor', 'note'), rtf_rows))
    if launchers:
        names = sorted({k for lr in launchers.values() for k in (lr.get('cpu_per_sim_s') or {})
                        if k != 'total'}, key=lambda k: (k == 'launcher', k))
        cost_rows = [(name.replace('_', ' '), *_cost_cells(lr, names + ['total']))
                     for name, lr in launchers.items() if lr and 'error' not in lr]
        if cost_rows:
            parts.append('CPU seconds per sim second of each process over the job (from '
                         "`/proc`, the launcher's `cpu_per_sim_s`); the launcher process "
                         'records the run.')
            parts.append(md_table(['run'] + [n.replace('_', ' ') for n in names] + ['total'],
                                  cost_rows, 'l' + 'r' * (len(names) + 1)))
    parts.append(_figure(results, 'throughput', 'items per minute per mode and seed'))
    return '\n\n'.join(parts)


RENDER = {'paths': _paths, 'solvers': _solvers, 'payload': _payload, 'sync': _sync,
          'singularity': _singularity, 'foresight': _foresight, 'throughput': _throughput}


def render(results: dict) -> str:
    """Return ``RESULTS.md`` for one run's results."""
    meta = results['meta']
    sections = ', '.join(f'{k} {v:.0f} s' for k, v in meta['sections_s'].items()
                         if v is not None)
    head = [
        '# Results, measured',
        '',
        f'Generated by `{meta["command"] or "scripts/benchmark.py"}` on {meta["date"]}'
        + (' — **smoke run: tiny sizes, the figures are rough**' if meta['smoke'] else '')
        + f'. Machine: {meta["cpu"]}, {meta["cores"]} cores (load {num(meta["load_1min"], 2)} '
        f'at the start), {meta["system"]}, Python {meta["python"]}, numpy {meta["numpy"]}. '
        f'Wall time {meta["wall_s"]:.0f} s ({sections}); CPU time {meta["cpu_s"]:.0f} s '
        '(this process and the launcher run: on a quiet machine the wall time is close to it).',
        '',
        'The design documents (`../shared/seeds/`) print results that were never measured. '
        'Every "seeds\' claim" below is a quote from them, with the section it comes from; '
        'every other figure was measured by this run, on this machine. SPEC targets are from '
        '`../shared/SPEC.md` §5. Regenerate with `.venv/bin/python scripts/benchmark.py`.',
        '',
        '## Summary',
        '',
        md_table(('what', "seeds' claim", 'measured here', 'SPEC target', 'target'),
                 headline(results)),
    ]
    body = []
    for key, title in TITLES.items():
        data = results.get(key)
        text = RENDER[key](data, results) if _usable(data) else _unusable(data)
        body += ['', f'## {title}', '', text]
    return '\n'.join(head + body) + '\n'


README_BEGIN = '<!-- benchmark:summary:begin -->'
README_END = '<!-- benchmark:summary:end -->'


def readme_block(results: dict) -> str:
    """Return the README's generated block: the summary table and where it comes from."""
    meta = results['meta']
    return '\n'.join([
        README_BEGIN,
        f'*Generated by `scripts/benchmark.py` on {meta["date"]} ({meta["cpu"]}, '
        f'{meta["cores"]} cores, load {num(meta["load_1min"], 2)} at the start, '
        f'{meta["wall_s"] / 60:.1f} min wall, {meta["cpu_s"] / 60:.1f} min CPU); the full '
        "tables, the seeds' quotes and the figures are in [docs/RESULTS.md](docs/RESULTS.md).*",
        '',
        md_table(('what', "seeds' claim", 'measured here', 'SPEC target', 'target'),
                 headline(results)),
        README_END])


def update_readme(path, results: dict) -> bool:
    """Replace the block between the README markers; return False if there are none."""
    block = readme_block(results)
    inner = block[len(README_BEGIN):-len(README_END)].strip('\n')
    return replace_block(path, 'benchmark:summary', inner + '\n')


def block_markers(name: str):
    """Return the ``<!-- name:begin -->`` / ``<!-- name:end -->`` markers of a block."""
    return f'<!-- {name}:begin -->', f'<!-- {name}:end -->'


def replace_block(path, name: str, text: str) -> bool:
    """Replace the text between a generated block's markers; False if the file has none."""
    from pathlib import Path
    path = Path(path)
    begin, end = block_markers(name)
    old = path.read_text()
    if begin not in old or end not in old:
        return False
    before, rest = old.split(begin, 1)
    _, after = rest.split(end, 1)
    path.write_text(f'{before}{begin}\n{text.rstrip()}\n{end}{after}')
    return True


def kept_block(text: str, name: str) -> str:
    """Return a generated block of ``text`` with its markers ('' if none)."""
    begin, end = block_markers(name)
    if begin not in text or end not in text:
        return ''
    return begin + text.split(begin, 1)[1].split(end, 1)[0] + end
