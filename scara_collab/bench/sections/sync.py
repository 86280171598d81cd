"""Section 4, synchronisation: mirrored moves through the ROS graph (mirror error, start lag).

The measurement is :func:`scara_collab.bench.graph.measure` on
:func:`scara_collab.bench.graph.mirrored_targets`; this module is its summary row, its Markdown
(with the mirrored sorting job's in-step error, when section 7 ran it) and its figure.
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scara_collab.bench import graph
from scara_collab.bench.figures import canvas, save
from scara_collab.bench.markdown import m, md_table, met, mm, num, plural, quote
from scara_collab.bench.sections.base import Rows, Section, usable
from scara_collab.bench.sections.throughput import mirrored_run
from scara_collab.bench.util import Progress

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
    targets = graph.mirrored_targets(sizes.mirrored_moves)
    return graph.measure('line', targets, log=progress.note)


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
