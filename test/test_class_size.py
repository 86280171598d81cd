"""No class of the package over 250 lines, docstrings included.

A class that long does several things; its parts belong in objects of their own (the sorting
job is one, with its decisions and its moves beside it; the bridge has its outputs, its
execution and what holds the arms).
"""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / 'scara_collab'
LIMIT = 250


def class_lengths(root: Path = ROOT) -> dict:
    """Return the length in lines of every class of the package, by ``path:Name``."""
    out = {}
    for path in sorted(root.rglob('*.py')):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ClassDef):
                key = f'{path.relative_to(root).as_posix()}:{node.name}'
                out[key] = node.end_lineno - node.lineno + 1
    return out


def test_the_lengths_are_read_from_the_source(tmp_path):
    """A class's length runs from its ``class`` line to its last line."""
    source = 'class A:\n    """Doc."""\n\n    x = 1\n\n\nclass B:\n    pass\n'
    (tmp_path / 'm.py').write_text(source)
    assert class_lengths(tmp_path) == {'m.py:A': 4, 'm.py:B': 2}


def test_no_class_is_over_the_limit():
    """Every class of the package has at most 250 lines."""
    lengths = class_lengths()
    assert len(lengths) > 100  # the walk found the package
    too_long = {k: n for k, n in lengths.items() if n > LIMIT}
    assert not too_long, f'classes over {LIMIT} lines: {too_long}'
