"""Every docstring example (``>>>``) in the package and the benchmarks runs and shows its result.

The modules are found by scanning their source for ``>>>``, so an example added to any module
is run here, and an example that does not match the code fails the suite. Usage
sketches that cannot run on their own (they need a running node or a run folder) are written
without prompts.
"""
import doctest
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = (ROOT / 'scara_collab', ROOT / 'benchmarks')
FLAGS = doctest.NORMALIZE_WHITESPACE | doctest.ELLIPSIS


def modules_with_examples():
    """Return the dotted names of the packages' modules whose source holds ``>>>``, sorted."""
    return sorted('.'.join(path.relative_to(ROOT).with_suffix('').parts)
                  for package in PACKAGES for path in package.rglob('*.py')
                  if '>>>' in path.read_text(encoding='utf-8'))


MODULES = modules_with_examples()


def test_the_scan_finds_the_modules_with_examples():
    """The scan finds modules known to hold examples (so the parametrisation is not empty)."""
    assert {'scara_collab.core.kinematics', 'scara_collab.core.mirror',
            'benchmarks.util'} <= set(MODULES)


@pytest.mark.parametrize('name', MODULES)
def test_docstring_examples_run_and_match(name):
    """Every example in module ``name`` runs and prints what its docstring shows."""
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=FLAGS, report=False)
    assert result.attempted > 0, f'{name} contains ">>>" but doctest found no example in it'
    assert result.failed == 0, (f'{result.failed} of {result.attempted} examples in {name} '
                                'failed (the report is in the captured stdout)')
