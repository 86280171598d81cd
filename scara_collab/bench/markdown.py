"""The Markdown of ``RESULTS.md``: tables, numbers with their units, claims quoted, targets met.

Shared by the page frame (:mod:`scara_collab.bench.report`) and every section
(:mod:`scara_collab.bench.sections`), so a figure reads the same wherever it is printed.
"""
import math
from typing import Iterable, Optional, Sequence

from scara_collab.bench.claims import CLAIMS


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


def md_table(head: Sequence[str], rows: Iterable[Sequence[object]],
             align: Optional[str] = None) -> str:
    """Return a Markdown table; ``align`` is one of ``l r c`` per column (default left)."""
    align = align or 'l' * len(head)
    marks = {'l': '---', 'r': '---:', 'c': ':---:'}
    lines = ['| ' + ' | '.join(head) + ' |',
             '|' + '|'.join(marks[a] for a in align) + '|']
    for row in rows:
        lines.append('| ' + ' | '.join(str(c) for c in row) + ' |')
    return '\n'.join(lines)


def figure_link(results: dict, key: str, alt: str) -> str:
    """Return the image link of section ``key``'s figure, or why it was not drawn."""
    name = (results.get('figures') or {}).get(key, '')
    if name.endswith('.png'):
        return f'![{alt}](figures/{name})'
    return f'*(figure not drawn: {name or "no data"})*'
