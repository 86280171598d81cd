"""No import cycle in the package: every module's imports, read with ``ast``, form no loop.

Every import counts: at module level, under ``if TYPE_CHECKING:``, inside functions. An import
of a package's name (``from scara_collab.core import sorting``) is an import of that
submodule when there is one, else of the package's ``__init__``.
"""
import ast
from pathlib import Path
import re
from typing import Dict, List, Set

PACKAGE = 'scara_collab'
ROOT = Path(__file__).resolve().parents[1] / PACKAGE


def modules(root: Path = ROOT) -> Dict[str, Path]:
    """Return every module of the package by its dotted name (a package by its own name)."""
    found = {}
    for path in sorted(root.rglob('*.py')):
        parts = list(path.relative_to(root.parent).with_suffix('').parts)
        if parts[-1] == '__init__':
            parts = parts[:-1]
        found['.'.join(parts)] = path
    return found


def imports(name: str, path: Path, known: Dict[str, Path]) -> Set[str]:
    """Return the package's modules that module ``name`` (at ``path``) imports, anywhere in it."""
    is_package = path.name == '__init__.py'
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name in known}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:  # relative: from the module's package, up level - 1 more
                here = name.split('.') if is_package else name.split('.')[:-1]
                here = here[:len(here) - (node.level - 1)]
                base = '.'.join(here + ([base] if base else []))
            for alias in node.names:
                sub = f'{base}.{alias.name}'
                if sub in known:
                    out.add(sub)
                elif base in known:
                    out.add(base)
    out.discard(name)
    return out


def graph(root: Path = ROOT) -> Dict[str, Set[str]]:
    """Return the package's import graph: each module's imported modules."""
    known = modules(root)
    return {name: imports(name, path, known) for name, path in known.items()}


def cycles(edges: Dict[str, Set[str]]) -> List[List[str]]:
    """Return one cycle (``[a, b, ..., a]``) per strongly connected group of modules."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    groups: List[Set[str]] = []

    def visit(v: str) -> None:  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.add(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(group)

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return [_loop(group, edges) for group in groups]


def _loop(group: Set[str], edges: Dict[str, Set[str]]) -> List[str]:
    """Return a path that goes round ``group`` (a strongly connected set) back to its start."""
    start = min(group)
    paths = {start: [start]}
    todo = [start]
    while todo:  # breadth first, inside the group, back to the start
        v = todo.pop(0)
        for w in sorted(edges[v] & group):
            if w == start:
                return paths[v] + [start]
            if w not in paths:
                paths[w] = paths[v] + [w]
                todo.append(w)
    raise AssertionError(f'{sorted(group)} is not strongly connected')


def test_the_walker_sees_every_kind_of_import(tmp_path):
    """Module level, relative, under TYPE_CHECKING and inside a function: each one counts."""
    pkg = tmp_path / 'pkg'
    (pkg / 'sub').mkdir(parents=True)
    (pkg / '__init__.py').write_text('')
    (pkg / 'sub' / '__init__.py').write_text('VALUE = 1\n')
    (pkg / 'a.py').write_text('from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n'
                              '    from pkg.b import B\n')
    (pkg / 'b.py').write_text('def f():\n    from .sub import c\n')
    (pkg / 'sub' / 'c.py').write_text('import pkg.a\nfrom pkg.sub import VALUE\n')
    edges = graph(pkg)
    assert edges['pkg.a'] == {'pkg.b'} and edges['pkg.b'] == {'pkg.sub.c'}
    assert edges['pkg.sub.c'] == {'pkg.a', 'pkg.sub'}
    assert cycles(edges) == [['pkg.a', 'pkg.b', 'pkg.sub.c', 'pkg.a']]
    assert cycles({'x': {'y'}, 'y': set()}) == []


def test_no_module_of_the_package_imports_itself_round_a_loop():
    """The package's import graph has no cycle."""
    found = cycles(graph())
    assert not found, 'import cycles: ' + '; '.join(' -> '.join(c) for c in found)


def test_the_benchmarks_have_no_loop_and_the_package_never_imports_them():
    """benchmarks/ (beside the package, not installed) has no cycle; no package module uses it."""
    benchmarks = ROOT.parent / 'benchmarks'
    found = cycles(graph(benchmarks))
    assert len(modules(benchmarks)) > 10  # the walk found the benchmarks
    assert not found, 'import cycles: ' + '; '.join(' -> '.join(c) for c in found)
    uses = re.compile(r'^\s*(?:from|import)\s+benchmarks\b', re.M)
    users = [str(p.relative_to(ROOT)) for p in ROOT.rglob('*.py') if uses.search(p.read_text())]
    assert not users, f'package modules importing the benchmarks: {users}'
