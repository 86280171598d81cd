"""Section 2, solver speed: the motion core against reference implementations, same run.

The measurement is :func:`scara_collab.bench.solvers.measure` (IK against a textbook numpy IK,
Jacobian and dynamics against Pinocchio, capsule distances against coal); this module is its
summary row, its Markdown and its figure.
"""
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from scara_collab.bench import solvers
from scara_collab.bench.claims import CLAIMS
from scara_collab.bench.figures import canvas, save
from scara_collab.bench.markdown import md_table, met, num, quote
from scara_collab.bench.sections.base import Rows, Section
from scara_collab.bench.util import fmt_seconds, Progress

TARGETS = {
    'ik_latency': 5e-6,            # s, one target
    'ik_rate': 1e6,                # targets/s, vectorised
}
"""The SPEC's targets (``../shared/SPEC.md`` §5), as numbers."""


@dataclass(frozen=True)
class Sizes:
    """How long the solvers are timed."""

    quick_solvers: bool = False      # few iterations: rough figures


def measure(sizes: Sizes, progress: Progress, scratch: Path) -> dict:
    """Time the motion core and its references."""
    return solvers.measure(sizes.quick_solvers, progress.note)


def solver_row(data: dict, prefix: str) -> Optional[dict]:
    """Return the first row whose ``what`` starts with ``prefix`` (None if there is none)."""
    for r in data['rows']:
        if r['what'].startswith(prefix):
            return r
    return None


def summary(s: dict) -> Rows:
    """Return the summary row: IK latency, one target and vectorised."""
    one = solver_row(s, 'IK, one target')
    vec = next(r for r in s['rows'] if r['what'].startswith('IK,') and r['kind'] == 'rate')
    return [('IK latency', CLAIMS['ik_latency'].figure,
             f'{fmt_seconds(one["ours"])} one target; '
             f'{vec["ours"] / 1e6:.3g} M targets/s vectorised',
             '≤ 5 µs; ≥ 10⁶/s',
             met(one['ours'] <= TARGETS['ik_latency'] and vec['ours'] >= TARGETS['ik_rate']))]


def markdown(s: dict, results: dict) -> str:
    """Return the section's text: the claims, every timing beside its reference, the machine."""
    rows = []
    for r in s['rows']:
        d = solvers.display(r)
        claim = CLAIMS['ik_latency'].figure if r['what'] == 'IK, one target' else ''
        target = f'{r["target"]} {met(r["met"])}'.strip() if r['target'] else ''
        rows.append((r['what'], d['ours'], d['reference'], d['ratio'], r['note'], target,
                     claim))
    meta = results['meta']
    sizes = s['sizes']
    ik_one = solver_row(s, 'IK, one target')
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
        f'{num(meta["load_1min"], 2)}): absolute figures are noisy, ratios less so.'])


def figure(data: dict, path: Path) -> None:
    """Speed-up of the motion core over each reference, log scale."""
    rows = [r for r in data['rows'] if r['speedup'] is not None]
    fig, ax = canvas(8.0, 0.32 * len(rows) + 1.2)
    y = np.arange(len(rows))[::-1]
    vals = np.array([r['speedup'] for r in rows])
    ax.barh(y, vals, color=['tab:green' if v >= 1 else 'tab:red' for v in vals], alpha=0.7)
    ax.set_xscale('log')
    ax.set_xlim(min(vals.min(), 1.0) / 2, max(vals.max(), 1.0) * 4)
    ax.axvline(1.0, color='k', lw=0.8)
    ax.set_yticks(y)
    ax.set_yticklabels([f'{r["what"]} (vs {r["reference_name"]})' for r in rows], fontsize=7)
    for yi, r in zip(y, rows):
        ax.text(r['speedup'], yi, f' {solvers.display(r)["ratio"]}', va='center', fontsize=7)
    ax.set_xlabel('how many times faster ours is (log; < 1 = slower)')
    ax.set_title('motion core vs references, same run', fontsize=10)
    save(fig, path)


SECTION = Section(
    key='solvers', title='solver speed vs reference implementations',
    heading='Solver speed, against reference implementations', measure=measure,
    markdown=markdown, summary=summary, figure=figure,
    figure_alt='speed-up over the references', full=Sizes(), smoke=Sizes(quick_solvers=True))
