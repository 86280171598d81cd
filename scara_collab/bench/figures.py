"""The canvas of the benchmark's figures (small PNGs); each section draws its own.

Matplotlib's Agg canvas is used directly (``matplotlib.figure.Figure``: no display, no pyplot
state). The figure of a section is its ``figure(data, path)``
(:class:`~scara_collab.bench.sections.base.Section`); the suite draws them all.
"""
from pathlib import Path

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
