"""What a section of the benchmark is: its measurement, Markdown, summary rows and figure."""
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, List, Optional, Sequence

from scara_collab.bench.util import Progress

Rows = List[Sequence[str]]


@dataclass(frozen=True)
class Section:
    """One section of the benchmark and of ``RESULTS.md``, everything about it in one module.

    :ivar key: the results key, the ``--only`` name and the figure's file name (``<key>.png``).
    :ivar title: the name on the progress lines.
    :ivar heading: the heading in ``RESULTS.md``, without its number (the place in
        :data:`~scara_collab.bench.sections.SECTIONS` numbers it).
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
