"""The whole benchmark: every section in one run, with progress, figures and ``RESULTS.md``.

:func:`run` measures the sections of :data:`~scara_collab.bench.sections.SECTIONS` (each with
its sizes of the full run, or of the seconds-long smoke run), draws their figures and writes
the report (:mod:`scara_collab.bench.report`). A section that fails is reported as failed
(with the error) and the others still run.
"""
from dataclasses import asdict
from pathlib import Path
import resource
import tempfile
import time
import traceback
from typing import Dict, List, Optional, Sequence

from scara_collab.bench import report
from scara_collab.bench.sections import SECTIONS
from scara_collab.bench.sections.base import usable
from scara_collab.bench.util import machine, Progress, write_json


def cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and its finished children so far."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def draw_figures(results: dict, directory: Path) -> Dict[str, str]:
    """Draw the figure of every section that has data; return ``{key: file name or error}``."""
    out = {}
    for section in SECTIONS:
        data = results.get(section.key)
        if not usable(data):
            continue
        name = f'{section.key}.png'
        try:
            section.figure(data, Path(directory) / name)
            out[section.key] = name
        except Exception as exc:  # noqa: B902 - a figure must not lose the report
            out[section.key] = f'error: {type(exc).__name__}: {exc}'
    return out


def run(out: Path, smoke: bool = False, only: Optional[Sequence[str]] = None,
        progress: Optional[Progress] = None, json_path: Optional[Path] = None,
        command: str = '') -> Dict[str, object]:
    """Measure the sections, write ``out/RESULTS.md`` and ``out/figures/*.png``.

    :param smoke: the sections' smoke sizes (seconds, not minutes) instead of the full ones.
    :param only: section keys to run (default all); the others are reported as not run.
    :param json_path: also write every measured value here.
    :param command: the command line, quoted in the report.
    :return: ``{'meta': ..., <section key>: data or {'error': ...}, 'figures': ...}``.
    """
    progress = progress or Progress()
    out = Path(out)
    (out / 'figures').mkdir(parents=True, exist_ok=True)
    sizes = {s.key: asdict(s.sizes(smoke)) for s in SECTIONS if s.sizes(smoke) is not None}
    results: Dict[str, object] = {
        'meta': {**machine(), 'smoke': smoke, 'sizes': sizes, 'command': command,
                 'date': time.strftime('%Y-%m-%d %H:%M %Z'), 'sections_s': {}}}
    with tempfile.TemporaryDirectory(prefix='scara_bench_') as scratch:
        for section in SECTIONS:
            if only and section.key not in only:
                results[section.key] = {'skipped': True}
                continue
            try:
                with progress.section(section.title):
                    results[section.key] = section.measure(section.sizes(smoke), progress,
                                                           Path(scratch))
            except Exception as exc:  # noqa: B902 - one broken section must not hide the rest
                results[section.key] = {'error': f'{type(exc).__name__}: {exc}',
                                        'traceback': traceback.format_exc()}
            results['meta']['sections_s'][section.key] = progress.sections.get(section.title)
    with progress.section('figures and report'):
        results['figures'] = draw_figures(results, out / 'figures')
        results['meta']['wall_s'] = progress.elapsed()
        results['meta']['cpu_s'] = cpu_seconds()
        target = out / 'RESULTS.md'
        # the blocks other scripts wrote into the page (report.KEPT_BLOCKS) are kept
        previous = target.read_text() if target.is_file() else ''
        target.write_text(report.render(results, previous))
    if json_path:
        write_json(json_path, results, indent=1)
    return results


def failed(results: Dict[str, object]) -> List[str]:
    """Return the keys of the sections that failed."""
    return [s.key for s in SECTIONS
            if isinstance(results.get(s.key), dict) and 'error' in results[s.key]]
