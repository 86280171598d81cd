"""Section 6, collision foresight: conflicts of random crossing moves, found and resolved.

The measurement is :func:`scara_collab.bench.foresight.measure`; this module is its statistics,
summary row, Markdown (with the sorting jobs' separations, when section 7 ran them) and figure.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Iterable, Optional

import numpy as np

from scara_collab.bench import foresight
from scara_collab.bench.claims import CLAIMS
from scara_collab.bench.figures import canvas, save
from scara_collab.bench.markdown import m, md_table, met, num, plural, quote
from scara_collab.bench.sections.base import Rows, Section, usable
from scara_collab.bench.util import fmt_seconds, Progress, spread


@dataclass(frozen=True)
class Sizes:
    """How many crossing pairs are drawn, and how many of the conflicts run in physics."""

    foresight_pairs: int = 200
    foresight_execute: int = 30


def measure(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    """Draw, schedule and (some) execute the crossing pairs."""
    return foresight.measure(sizes.foresight_pairs, sizes.foresight_execute, log=progress.note)


def _median(values: Iterable[float]) -> Optional[float]:
    x = list(values)
    return float(np.median(x)) if x else None


def stats(data: dict) -> Dict[str, object]:
    """Return the figures of the study: conflicts, foresight, outcomes, delays, separations."""
    pairs = data['pairs']
    conflicts = [p for p in pairs if p['conflict']]
    executed = [p['executed_min_m'] for p in pairs if p['executed_min_m'] is not None]
    planned = [p['planned_min_m'] for p in pairs if p['planned_min_m'] is not None]
    return {
        'n': len(pairs), 'conflicts': len(conflicts),
        'touch': sum(p['impact_s'] is not None for p in conflicts),
        'foresight': spread(p['foresight_s'] for p in conflicts),
        'foresight_median': _median(p['foresight_s'] for p in conflicts),
        'impact': spread(p['impact_s'] for p in conflicts),
        'impact_median': _median(p['impact_s'] for p in conflicts if p['impact_s'] is not None),
        'outcomes': {k: sum(p['outcome'] == k for p in pairs)
                     for k in ('clear', 'delayed', 'waits')},
        'conflict_outcomes': {k: sum(p['outcome'] == k for p in conflicts)
                              for k in ('clear', 'delayed', 'waits')},
        'delay': spread(p['delay_s'] for p in conflicts if p['delay_s'] is not None),
        'delay_median': _median(p['delay_s'] for p in conflicts if p['delay_s'] is not None),
        'decision': spread(p['decision_s'] for p in pairs),
        'decision_median': _median(p['decision_s'] for p in pairs),
        'unresolved': spread(p['unresolved_min_m'] for p in conflicts),
        'planned': spread(planned),
        'executed': spread(executed),
        'planned_breaches': sum(v < data['margin'] for v in planned),
        'executed_breaches': sum(v < data['margin'] for v in executed),
    }


def summary(f: dict) -> Rows:
    """Return the summary row: conflicts found, how early, breaches planned and executed."""
    st = stats(f)
    return [('collision foresight (crossing pairs)', CLAIMS['foresight'].figure,
             f'{st["conflicts"]} conflicts in {st["n"]} pairs, all found at the decision,'
             f' {num(st["foresight"]["min"], 2, "s")} (min) before the margin would '
             f'break; {st["executed_breaches"]} breaches in {st["executed"]["n"]} '
             'executed', 'resolved at planning time; zero breaches',
             met(st['planned_breaches'] == 0 and st['executed_breaches'] == 0))]


def markdown(f: dict, results: dict) -> str:
    """Return the section's text: the claims, the study's figures, the jobs' separations."""
    st = stats(f)
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
    if usable(t):
        seps = [r['min_separation_m'] for r in t['runs'] if r.get('mode') != 'single'
                and r.get('min_separation_m') is not None]
        if t.get('mirrored') and t['mirrored'].get('min_separation_m') is not None:
            seps.append(t['mirrored']['min_separation_m'])
        if seps:
            rows.append((f'sorting jobs with both arms ({plural(len(seps), "run")}, section 7): '
                         'smallest separation, min / mean',
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
        'e-stop below the margin) is the safety net behind this.'])


def figure(data: dict, path: Path) -> None:
    """Foresight of the conflicts found; separations unresolved, planned and executed."""
    pairs = data['pairs']
    conflicts = [p for p in pairs if p['conflict']]
    fig, (ax, ax2) = canvas(9.5, 3.6, 2)
    if conflicts:
        ax.hist([p['foresight_s'] for p in conflicts], bins=20, color='tab:blue', alpha=0.7,
                label='margin broken (predicted)')
        impacts = [p['impact_s'] for p in conflicts if p['impact_s'] is not None]
        if impacts:
            ax.hist(impacts, bins=20, color='tab:red', alpha=0.5, label='capsules touch')
    ax.axvline(0.2, color='k', ls='--', lw=1)
    ax.text(0.21, ax.get_ylim()[1] * 0.9, 'seeds: 200 ms', fontsize=7)
    ax.axvline(data['lead'], color='0.5', ls=':', lw=1)
    ax.text(data['lead'] + 0.01, ax.get_ylim()[1] * 0.8, 'motion starts', fontsize=7,
            color='0.4')
    ax.set_xlabel('time after the decision (s)')
    ax.set_ylabel('conflicting pairs')
    ax.set_title(f'{len(conflicts)} conflicts in {len(pairs)} crossing pairs', fontsize=10)
    ax.legend(fontsize=7)
    bins = np.linspace(-0.12, 0.42, 55)
    un = [p['unresolved_min_m'] for p in pairs if p['conflict']]
    pl = [p['planned_min_m'] for p in pairs if p['conflict'] and p['planned_min_m'] is not None]
    ex = [p['executed_min_m'] for p in pairs if p['executed_min_m'] is not None]
    for vals, colour, label in ((un, 'tab:red', 'started together (no resolution)'),
                                (pl, 'tab:blue', 'with the delay, planned'),
                                (ex, 'tab:green', 'with the delay, executed in physics')):
        if vals:
            ax2.hist(np.clip(vals, bins[0], bins[-1]), bins=bins, color=colour, alpha=0.55,
                     label=label)
    ax2.axvline(data['margin'], color='k', lw=1)
    ax2.text(data['margin'], ax2.get_ylim()[1] * 0.9, ' margin', fontsize=7)
    ax2.set_xlabel('smallest arm-to-arm distance over the pair (m)')
    ax2.set_ylabel('pairs')
    ax2.set_title('separation of the conflicting pairs', fontsize=10)
    ax2.legend(fontsize=7)
    save(fig, path)


SECTION = Section(
    key='foresight', title='collision foresight on crossing moves',
    heading='Collision foresight and margins', measure=measure, markdown=markdown,
    summary=summary, figure=figure, figure_alt='foresight and separation histograms',
    full=Sizes(), smoke=Sizes(foresight_pairs=6, foresight_execute=2))
