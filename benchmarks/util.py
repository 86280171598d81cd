"""What the benchmarks share: the machine, timing, progress lines, Markdown tables, figures."""
from contextlib import contextmanager
from dataclasses import dataclass
import json
import math
import os
from pathlib import Path
import platform
import re
import sys
import time
import timeit
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from benchmarks.claims import CLAIMS

Log = Callable[[str], None]
Rows = List[Sequence[str]]

#: the pages the benchmarks write into their folder (``docs/results/`` by default), and the
#: folder of the results page's figures beside them
RESULTS_PAGE, REALTIME_PAGE, LINE_PAGE, FIGURES = 'results.md', 'realtime.md', 'line.md', 'figures'


def machine() -> Dict[str, object]:
    """Describe this machine: CPU, cores, load, Python and numpy versions."""
    cpu = platform.processor() or platform.machine()
    if os.path.isfile('/proc/cpuinfo'):
        with open('/proc/cpuinfo') as f:
            cpu = next((ln.split(':', 1)[1].strip() for ln in f
                        if ln.startswith('model name')), cpu)
    return {'cpu': cpu, 'cores': os.cpu_count(), 'load_1min': os.getloadavg()[0],
            'python': platform.python_version(), 'numpy': np.__version__,
            'system': f'{platform.system()} {platform.release()}'}


def per_call(fn: Callable[[], object], number: int, repeat: int = 5) -> float:
    """Return the median seconds per call of ``fn`` over ``repeat`` runs of ``number`` calls."""
    return float(np.median(timeit.repeat(fn, number=number, repeat=repeat))) / number


class Progress:
    """Progress lines on stderr with the elapsed wall time: one per section."""

    def __init__(self):
        """Start the clock now."""
        self.start = time.monotonic()
        self.sections: Dict[str, float] = {}

    def elapsed(self) -> float:
        """Wall seconds since this object was made."""
        return time.monotonic() - self.start

    def note(self, text: str) -> None:
        """Print one line after the elapsed time."""
        print(f'[{self.elapsed():7.1f} s] {text}', file=sys.stderr, flush=True)

    @contextmanager
    def section(self, name: str) -> Iterator[None]:
        """Print the section's start, then its duration or its failure."""
        t0, status = time.monotonic(), 'done'
        self.note(f'{name} ...')
        try:
            yield
        except Exception as exc:
            status = f'FAILED ({type(exc).__name__}: {exc})'
            raise
        finally:
            self.sections[name] = time.monotonic() - t0
            self.note(f'{name} {status} in {self.sections[name]:.1f} s')


def fmt_seconds(seconds: Optional[float], digits: int = 3) -> str:
    """Format a duration with a readable unit: ``'3.52 µs'``, ``'14.7 ms'``, ``'0.838 s'``."""
    if seconds is None or not math.isfinite(seconds):
        return 'n/a'
    for unit, scale in (('s', 1.0), ('ms', 1e-3), ('µs', 1e-6)):
        if abs(seconds) >= scale:
            return f'{seconds / scale:.{digits}g} {unit}'
    return f'{seconds / 1e-9:.{digits}g} ns'


def spread(values: Iterable[Optional[float]]) -> Dict[str, float]:
    """Return n, mean, sample standard deviation, min, median and max of the finite values."""
    x = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if x.size == 0:
        return dict.fromkeys(('mean', 'std', 'min', 'median', 'max'), math.nan) | {'n': 0}
    return {'n': int(x.size), 'mean': float(x.mean()),
            'std': float(x.std(ddof=1)) if x.size > 1 else 0.0, 'min': float(x.min()),
            'median': float(np.median(x)), 'max': float(x.max())}


def write_json(path, data) -> None:
    """Write ``data`` to ``path`` as JSON, numpy arrays and scalars as lists and numbers."""
    def plain(x):
        return x.tolist() if isinstance(x, (np.ndarray, np.generic)) else str(x)
    Path(path).write_text(json.dumps(data, indent=1, default=plain))


def num(x: Optional[float], digits: int = 3, unit: str = '') -> str:
    """Format a number with ``digits`` significant digits and a unit (``'n/a'`` for none)."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return 'n/a'
    return f'{x:.{digits}g}' + (f' {unit}' if unit else '')


def mm(metres: Optional[float], digits: int = 3) -> str:
    """Format metres as millimetres."""
    return num(None if metres is None else metres * 1e3, digits, 'mm')


def met(flag: Optional[bool]) -> str:
    """Format a target check."""
    return '' if flag is None else ('**met**' if flag else '**not met**')


def quote(*keys: str) -> str:
    """Blockquote the design documents' claims ``keys`` with their sources."""
    return '\n>\n'.join(f'> {CLAIMS[k].quote} — *{CLAIMS[k].source}*' for k in keys)


def table(rows: Sequence[Dict[str, object]], align: str = '') -> str:
    """Return rows of dicts as a Markdown table, the first row's keys as the head, aligned ``l r``.

    >>> print(table([{'a': 1, 'b': 2}], 'lr'))
    | a | b |
    |---|---:|
    | 1 | 2 |
    """
    head = list(rows[0])
    marks = ''.join('---:|' if a == 'r' else '---|' for a in align.ljust(len(head), 'l'))
    body = ['| ' + ' | '.join(str(r.get(k, '')) for k in head) + ' |' for r in rows]
    return '\n'.join(['| ' + ' | '.join(head) + ' |', '|' + marks] + body)


def axes(width: float, height: float, ncols: int = 1) -> Tuple[Any, List[Any]]:
    """Return ``(figure, [axes])``: a constrained-layout Agg figure, ``ncols`` axes in a row."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(width, height), layout='constrained')
    return fig, list(np.atleast_1d(fig.subplots(1, ncols)))


def finish(ax, xlabel: str, ylabel: str, title: str, hlines: Dict[float, str] = None) -> None:
    """Label ``ax``, draw dotted reference lines ``{y: text}``, add the legend if it has one."""
    for y, text in (hlines or {}).items():
        ax.axhline(y, color='k', lw=0.8, ls=':')
        ax.annotate(text, (0.01, y), xycoords=('axes fraction', 'data'), fontsize=7,
                    textcoords='offset points', xytext=(0, 3))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)


@dataclass(frozen=True)
class ResultsSection:
    """A numbered section of the results page (``key``: ``--only`` and ``figures/<key>.png``)."""

    key: str
    title: str
    heading: str
    claims: Tuple[str, ...]
    measure: Callable[[bool, Path], dict]
    tables: Callable[[dict], List[str]]
    summary: Callable[[dict], Rows]
    figure: Callable[[dict], Any]
    figure_alt: str


def put_block(page: str, name: str, heading: str, body: str) -> str:
    """Return ``page`` with block ``name``: between its markers, else under ``## heading``."""
    begin, end = f'<!-- {name}:begin -->', f'<!-- {name}:end -->'
    block = f'{begin}\n{body.strip()}\n{end}'
    if begin in page and end in page:
        before, rest = page.split(begin, 1)
        return before + block + rest.split(end, 1)[1]
    bare = re.sub(r'^\d+\. ', '', heading)
    found = re.search(rf'^## (\d+\. )?{re.escape(bare)}\n', page, re.M)
    if found:
        after = re.search(r'^## ', page[found.end():], re.M)
        stop = found.end() + after.start() if after else len(page)
        return f'{page[:found.end()]}\n{block}\n\n{page[stop:]}'
    return f'{page.rstrip()}\n\n## {heading}\n\n{block}\n'.lstrip()


def write_block(path: Path, name: str, heading: str, body: str,
                title: str = '# Results, measured') -> None:
    """Write ``body`` as the block ``name`` of the page at ``path`` (made with ``title``)."""
    path = Path(path)
    page = path.read_text() if path.is_file() else f'{title}\n'
    path.write_text(put_block(page, name, heading, body))


def usable(data) -> bool:
    """Return True if a section's results are data: it ran and did not fail."""
    return isinstance(data, dict) and 'error' not in data and not data.get('skipped')
