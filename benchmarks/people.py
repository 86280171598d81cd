"""A person in the cell through the launcher (``--only people``): safety, liveness, cost.

Each scenario (``pass-by``, ``inlet``, ``middle``, ``random``) runs beside the same seed
without a person, at the rated feed: in lockstep for every seed, side by side (two launchers
at once, each on a ROS domain of its own: their CPU per sim second is compared under the same
load), and with ``--lockstep off --rtf 1`` for the first two (``--realtime-seeds``), once
every lockstep pair has run, one after the other (two cells in real time on the machine's two
cores would starve each other's scans). ``--people nobody`` runs the scanners and the monitor
with nobody in the cell (their cost alone). Per run, from its ``summary.json``: items sorted
and missed, the person block (the least ``S - S_p`` while an
arm moved and contacts, from the ground truth; protective stops, slow-downs, the slowest
return to full speed; items missed for the person), the arms' least separation, emergency
stops and the exit code; the CPU per sim second of the run and of its person-free twin.
docs/people.md explains every figure; the targets are the issue's.
"""
import os
from pathlib import Path
import tempfile
import time
from typing import Dict, List, Optional, Sequence

from benchmarks.job_in_process import default_feed
from benchmarks.launched import Launch, publish, stamp, use_domain
from benchmarks.util import Log, table

SCENARIOS = ('pass-by', 'inlet', 'middle', 'random')
#: every scenario the section can run (``--people``): ``nobody`` is the cost of the scanners and
#: the monitor alone, and a check that they slow no arm for nothing
CHOICES = SCENARIOS + ('nobody',)
#: each arm back at full speed within this many sim s of the person leaving its S_p
RESUME = 1.5
#: inlet: at least this share of what the same seed sorts without the person
INLET_SHARE = 0.9
#: how many of the seeds run in real time too (the first ones)
REALTIME_SEEDS = 2


def pair(scenario: str, seed: int, duration: float, out: Path, realtime: bool,
         log: Log) -> Dict[str, object]:
    """Run ``scenario`` and its person-free twin side by side; return the row of the pair."""
    flags = ['--seed', str(seed), '--feed-interval', f'{default_feed():g}']
    if realtime:
        flags += ['--lockstep', 'off']
    rtf = 1.0 if realtime else 0.0
    runs, done = [], []
    for k, person in enumerate((scenario, None)):
        domain = use_domain(seed * 10 + k + (5 if realtime else 0))
        env = {'ROS_DOMAIN_ID': str(domain), 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
        folder = out / f'{scenario}_{seed}_{"rt" if realtime else "ls"}_{person or "none"}'
        runs.append(Launch('collaborative', duration, folder, rtf, env=dict(os.environ, **env),
                           flags=flags + (
                               ['--person', person] if person else [])))
        if realtime:  # one at a time: two real-time cells on two cores starve each other
            done.append(runs.pop().finish(duration * 4 + 300))
    with_person, without = done or [r.finish(duration * 4 + 300) for r in runs]
    row = _row(scenario, seed, realtime, with_person, without)
    log(f'{scenario} seed {seed} {"real time" if realtime else "lockstep"}: sorted '
        f'{row["sorted"]} vs {row["sorted_without"]} without, margin {row["min_ssm_margin_m"]}, '
        f'exit {row["exit"]}')
    return row


def _row(scenario: str, seed: int, realtime: bool, s: Dict, base: Dict) -> Dict[str, object]:
    person = s.get('person') or {}
    cpu = (s.get('cpu_per_sim_s') or {}).get('total')
    cpu_base = (base.get('cpu_per_sim_s') or {}).get('total')
    return {
        'scenario': scenario, 'seed': seed, 'clock': 'real time' if realtime else 'lockstep',
        'exit': s.get('exit_code'), 'sorted': s.get('sorted'),
        'sorted_without': base.get('sorted'), 'missed': s.get('missed'),
        'missed_for_person': person.get('missed_due_to_person'),
        'min_ssm_margin_m': _round(person.get('min_ssm_margin_m')),
        'contacts_while_moving': person.get('contacts_while_moving'),
        'protective_stops': person.get('protective_stops'),
        'stop_s': _round(person.get('stop_seconds'), 1),
        'slowed_s': _round(person.get('slowed_seconds'), 1),
        'slowdowns': person.get('slowdowns'), 'false_slowdowns': person.get('false_slowdowns'),
        'resume_s_max': _round(person.get('resume_seconds_max'), 2),
        'min_arm_sep_m': _round(s.get('min_separation_m')),
        'emergency_stops': len(s.get('emergency_stops') or []),
        'cpu_s_per_sim_s': _round(cpu), 'cpu_without': _round(cpu_base),
        'cpu_ratio': _round(cpu / cpu_base if cpu and cpu_base else None, 2),
    }


def _round(x: Optional[float], digits: int = 3) -> Optional[float]:
    return None if x is None else round(float(x), digits)


def verdict(rows: Sequence[Dict[str, object]]) -> List[str]:
    """Return the targets each row misses (empty: every target met)."""
    bad = []
    for r in rows:
        where = f'{r["scenario"]} seed {r["seed"]} ({r["clock"]})'
        margin = r['min_ssm_margin_m']
        if r['exit'] != 0:
            bad.append(f'{where}: exit {r["exit"]}')
        if margin is not None and margin < 0.0:
            bad.append(f'{where}: S - S_p {margin} m while an arm moved')
        if r['contacts_while_moving']:
            bad.append(f'{where}: {r["contacts_while_moving"]} contacts while moving')
        if r['emergency_stops']:
            bad.append(f'{where}: {r["emergency_stops"]} emergency stops')
        if r['resume_s_max'] is not None and r['resume_s_max'] > RESUME:
            bad.append(f'{where}: full speed {r["resume_s_max"]} s after clear')
        if r['min_arm_sep_m'] is not None and r['min_arm_sep_m'] < 0.1:
            bad.append(f'{where}: arms {r["min_arm_sep_m"]} m apart')
        if r['clock'] == 'lockstep' and r['scenario'] in ('pass-by', 'nobody') and (
                r['sorted'] != r['sorted_without'] or r['slowdowns']):
            bad.append(f'{where}: {r["scenario"]} sorted {r["sorted"]} (without: '
                       f'{r["sorted_without"]}), {r["slowdowns"]} slow-downs')
        if (r['clock'] == 'lockstep' and r['scenario'] == 'inlet' and r['sorted'] is not None
                and r['sorted_without'] and r['sorted'] < INLET_SHARE * r['sorted_without']):
            bad.append(f'{where}: inlet sorted {r["sorted"]} < {INLET_SHARE} x '
                       f'{r["sorted_without"]}')
    return bad


def section(args, page: Path, command: str, log: Log) -> bool:
    """Run the scenarios into a block of ``page``; True if every target was met.

    The default scenarios write the ``people`` block; another set (``--people``) a block of its
    own beside it (``people-nobody``), so a partial run never replaces the full table.

    :raises ValueError: for a negative ``--realtime-seeds``.
    """
    out = Path(tempfile.mkdtemp(prefix='scara_people_'))
    duration = args.duration or 240.0
    seeds = args.seeds or [1, 2, 3, 4, 5]
    scenarios = getattr(args, 'people', None) or SCENARIOS
    start = time.monotonic()
    realtime = getattr(args, 'realtime_seeds', None)
    realtime = REALTIME_SEEDS if realtime is None else realtime
    if realtime < 0:
        raise ValueError(f'--realtime-seeds must be 0 or more, got {realtime}')
    rows = [pair(scenario, seed, duration, out, False, log)
            for scenario in scenarios for seed in seeds]
    # the real-time runs last, one after the other: nothing else then loads the cores
    rows += [pair(scenario, seed, duration, out, True, log)
             for scenario in scenarios for seed in seeds[:realtime]]
    rows.sort(key=lambda r: (scenarios.index(r['scenario']), r['seed'], r['clock']))
    bad = verdict(rows)
    lock = [r for r in rows if r['clock'] == 'lockstep' and r['cpu_ratio']]
    passby = [r['cpu_ratio'] for r in lock if r['scenario'] == 'pass-by']
    text = '\n\n'.join(
        [stamp(command, start, f'{duration:g} sim s per run at the rated feed; each run beside '
               'the same seed without a person, side by side.'),
         table(rows),
         'CPU per sim s with the person over without it (pass-by, lockstep): '
         + (', '.join(f'{x:.2f}' for x in passby) or 'n/a')
         + (f'; mean {sum(passby) / len(passby):.2f}' if passby else '')
         + (f'; mean of every lockstep pair {sum(r["cpu_ratio"] for r in lock) / len(lock):.2f}'
            if lock else '') + '.',
         'Targets: ' + ('every one met.' if not bad else 'missed: ' + '; '.join(bad) + '.')])
    # the default scenarios are the page's block; others a block of their own beside it
    block = 'people' if tuple(scenarios) == SCENARIOS else 'people-' + '-'.join(scenarios)
    heading = 'A person in the cell: speed and separation monitoring' + (
        '' if block == 'people' else f' ({", ".join(scenarios)})')
    publish(text, page, block, heading, log, out)
    return not bad
