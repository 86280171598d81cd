"""Shared helpers of the benchmarks: the machine, timing, progress lines, number formats, JSON."""
from dataclasses import dataclass
import json
import math
import os
from pathlib import Path
import platform
import sys
import time
import timeit
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, TextIO

import numpy as np

from scara_collab.bench.claims import CLAIMS


Log = Callable[[str], None]


def cpu_name() -> str:
    """Return the CPU model name (``/proc/cpuinfo``), or what ``platform`` knows."""
    try:
        with open('/proc/cpuinfo') as f:
            for line in f:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> Dict[str, object]:
    """Describe this machine: CPU, cores, load, Python and numpy versions."""
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = None
    return {'cpu': cpu_name(), 'cores': os.cpu_count(), 'load_1min': load,
            'python': platform.python_version(), 'numpy': np.__version__,
            'system': f'{platform.system()} {platform.release()}'}


def per_call(fn: Callable[[], object], number: int, repeat: int = 5) -> float:
    """Return the median seconds per call of ``fn`` over ``repeat`` runs of ``number`` calls."""
    return float(np.median(timeit.repeat(fn, number=number, repeat=repeat))) / number


def stderr_log(msg: str) -> None:
    """Print a progress message to stderr at once."""
    print(msg, file=sys.stderr, flush=True)


class Progress:
    """Progress lines with the elapsed wall time: one per section, plus notes inside it.

    Example (on stdout here; the default stream is stderr)::

        >>> import sys
        >>> progress = Progress(sys.stdout)
        >>> with progress.section('payload response'):
        ...     progress.note('0 kg, PID')
        [    ... s] payload response ...
        [    ... s]    0 kg, PID
        [    ... s] payload response done in ... s
    """

    def __init__(self, stream: Optional[TextIO] = None):
        """Start the clock now; lines go to ``stream`` (default stderr)."""
        self.stream = stream if stream is not None else sys.stderr
        self.start = time.monotonic()
        self.sections: Dict[str, float] = {}

    def elapsed(self) -> float:
        """Wall seconds since this object was made."""
        return time.monotonic() - self.start

    def _line(self, text: str) -> None:
        print(f'[{self.elapsed():7.1f} s] {text}', file=self.stream, flush=True)

    def note(self, text: str) -> None:
        """Print one indented line (progress inside a section)."""
        self._line(f'   {text}')

    def section(self, name: str) -> '_Section':
        """Return a context manager that prints the section's start and its duration."""
        return _Section(self, name)


class _Section:
    def __init__(self, progress: Progress, name: str):
        self.progress, self.name = progress, name

    def __enter__(self) -> Progress:
        self.t0 = time.monotonic()
        self.progress._line(f'{self.name} ...')
        return self.progress

    def __exit__(self, exc_type, exc, tb) -> bool:
        took = time.monotonic() - self.t0
        self.progress.sections[self.name] = took
        status = 'done' if exc_type is None else f'FAILED ({exc_type.__name__}: {exc})'
        self.progress._line(f'{self.name} {status} in {took:.1f} s')
        return False


def fmt_seconds(seconds: Optional[float], digits: int = 3) -> str:
    """Format a duration with a readable unit: ``'3.52 µs'``, ``'14.7 ms'``, ``'0.838 s'``."""
    if seconds is None or not math.isfinite(seconds):
        return 'n/a'
    for unit, scale in (('s', 1.0), ('ms', 1e-3), ('µs', 1e-6), ('ns', 1e-9)):
        if abs(seconds) >= scale or unit == 'ns':
            return f'{seconds / scale:.{digits}g} {unit}'
    return f'{seconds:g} s'


def fmt_rate(per_second: float) -> str:
    """Format a throughput: ``'6.3 M/s'``, ``'850 k/s'``."""
    if per_second >= 1e6:
        return f'{per_second / 1e6:.3g} M/s'
    if per_second >= 1e3:
        return f'{per_second / 1e3:.3g} k/s'
    return f'{per_second:.3g} /s'


def spread(values: Iterable[float]) -> Dict[str, float]:
    """Return n, mean, sample standard deviation, min and max of the finite values."""
    x = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if x.size == 0:
        return {'n': 0, 'mean': float('nan'), 'std': float('nan'), 'min': float('nan'),
                'max': float('nan')}
    return {'n': int(x.size), 'mean': float(x.mean()),
            'std': float(x.std(ddof=1)) if x.size > 1 else 0.0,
            'min': float(x.min()), 'max': float(x.max())}


def _plain(x):
    """Return a numpy array as a list, a numpy scalar as a Python number (``json``'s hook)."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f'{type(x).__name__} is not JSON serialisable')


def write_json(path, data, indent: int = 2) -> None:
    """Write ``data`` to ``path`` as JSON, numpy arrays and scalars as lists and numbers.

    Example::

        >>> import json, tempfile
        >>> with tempfile.NamedTemporaryFile('r', suffix='.json') as f:
        ...     write_json(f.name, {'q': np.zeros(2), 'n': np.int64(3)}, indent=None)
        ...     json.load(f)
        {'q': [0.0, 0.0], 'n': 3}
    """
    with open(path, 'w') as f:
        json.dump(data, f, indent=indent, default=_plain)


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


DPI = 90


def canvas(width: float, height: float, ncols: int = 1):
    """Return ``(figure, axes)``: a constrained-layout Agg figure with ``ncols`` axes.

    :param width: inches.
    :param height: inches.
    """
    from matplotlib.figure import Figure
    fig = Figure(figsize=(width, height), layout='constrained')
    axes = fig.subplots(1, ncols)
    return fig, axes


def save(fig, path: Path) -> None:
    """Save ``fig`` as a PNG at the benchmark's resolution."""
    fig.savefig(path, dpi=DPI)


Rows = List[Sequence[str]]


@dataclass(frozen=True)
class Section:
    """One section of the benchmark and of ``RESULTS.md``, everything about it in one module.

    :ivar key: the results key, the ``--only`` name and the figure's file name (``<key>.png``).
    :ivar title: the name on the progress lines.
    :ivar heading: the heading in ``RESULTS.md``, without its number (the place in
        :data:`~scara_collab.bench.report.SECTIONS` numbers it).
    :ivar measure: ``measure(sizes, progress, scratch) -> data``: run the section with its
        sizes (:attr:`full` or :attr:`smoke`), notes on ``progress``, files under the
        ``scratch`` folder; return plain data (dicts, lists, floats, strings, arrays).
    :ivar markdown: ``markdown(data, results) -> text``: the section's body (the claims quoted,
        the tables, the prose; not the figure's link); ``results`` holds every section's data,
        for the figures one section quotes from another.
    :ivar summary: ``summary(data) -> rows`` of the summary table (what, seeds' claim,
        measured here, SPEC target, target met).
    :ivar figure: ``figure(data, path)``: draw the section's figure and save it as ``path``.
    :ivar figure_alt: the figure's alternative text in ``RESULTS.md``.
    :ivar full: the sizes of the full run, a frozen dataclass (None: the section has none).
    :ivar smoke: the sizes of the seconds-long smoke run.
    """

    key: str
    title: str
    heading: str
    measure: Callable[[Any, Progress, Path], dict]
    markdown: Callable[[dict, dict], str]
    summary: Callable[[dict], Rows]
    figure: Callable[[dict, Path], None]
    figure_alt: str
    full: Optional[Any] = None
    smoke: Optional[Any] = None

    def sizes(self, smoke: bool = False) -> Optional[Any]:
        """Return the sizes of the smoke run if ``smoke``, else of the full run."""
        return self.smoke if smoke else self.full


def usable(data) -> bool:
    """Return True if a section's results are data: it ran and did not fail."""
    return isinstance(data, dict) and 'error' not in data and not data.get('skipped')
