"""The README and docs/ stay linked, true to the code and free of history.

STYLE.md's *Documentation*: a README a newcomer reads in ten minutes (the two commands, what
they print, how to drive the cell, a map, links), the rest in ``docs/``, saying what the code
does now; history belongs in the git log. The generated pages (``docs/results/``, written by
``scripts/benchmark.py``) and the generated blocks between ``<!-- name:begin -->`` and
``<!-- name:end -->`` markers are the benchmarks': the blocks are not checked for history or
links, and the options the generated pages name are not checked.
"""
from pathlib import Path
import re

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
DOCS = sorted((ROOT / 'docs').rglob('*.md'))
GENERATED = ROOT / 'docs' / 'results'  # the pages scripts/benchmark.py writes
QUICK_START = ('./scripts/demo', './scripts/test')

BLOCK = re.compile(r'<!-- ([\w:-]+):begin -->.*?<!-- \1:end -->', re.S)
FENCE = re.compile(r'^```.*?^```', re.S | re.M)
CODE = re.compile(r'`[^`\n]*`')
LINK = re.compile(r'!?\[[^\]]*\]\(([^)\s]+)(?:\s+"[^"]*")?\)')
#: a commit hash: a word of 7-40 hex digits, with at least one digit and one letter
HASH = re.compile(r'\b(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])([0-9a-f]{7,40})\b')
ISSUE = re.compile(r'\bissues?\s+#?\d+\b|\(#\d+\)', re.I)
#: options of other programs the docs name (ROS 2, colcon), and argparse's own
FOREIGN_OPTIONS = {'--ros-args', '--params-file', '--packages-select', '--clock', '--help'}


def pages():
    """Return README.md and every Markdown page under docs/."""
    return [README] + DOCS


def name(page: Path) -> str:
    """Return ``page``'s path in the repository (a test id)."""
    return page.relative_to(ROOT).as_posix()


def without_generated(text: str) -> str:
    """Return ``text`` without its generated blocks (markers included)."""
    return BLOCK.sub('', text)


def prose(text: str) -> str:
    """Return ``text`` without generated blocks, fenced code and code spans."""
    return CODE.sub('', FENCE.sub('', without_generated(text)))


def slug(heading: str) -> str:
    """Return GitHub's anchor for a Markdown heading."""
    text = re.sub(r'[`*_]', '', heading.strip().lower())
    text = re.sub(r'[^\w\- ]', '', text)
    return text.replace(' ', '-')


def anchors(path: Path):
    """Return the anchors of ``path``'s headings."""
    text = FENCE.sub('', path.read_text(encoding='utf-8'))
    return {slug(m.group(1)) for m in re.finditer(r'^#{1,6}\s+(.+)$', text, re.M)}


def test_quick_start_is_the_two_commands_ci_runs():
    """The quick start is exactly two commands, both scripts exist, and CI runs the second."""
    text = README.read_text(encoding='utf-8')
    section = text[text.index('## Quick start'):]
    block = FENCE.search(section).group(0).splitlines()[1:-1]
    commands = [line.split('#')[0].strip() for line in block if line.strip()]
    assert commands == list(QUICK_START), commands
    for command in commands:
        script = ROOT / command
        assert script.is_file() and script.stat().st_mode & 0o111, command
    ci = [line.strip() for line in (ROOT / '.ci' / 'run').read_text().splitlines()
          if line.strip() and not line.lstrip().startswith('#')]
    assert ci[-1] == QUICK_START[1], f'.ci/run must end by running {QUICK_START[1]}: {ci[-1]}'


@pytest.mark.parametrize('page', pages(), ids=name)
def test_relative_links_resolve(page):
    """Every relative link (and image) points to a file that exists, and to a heading there."""
    broken = []
    for target in LINK.findall(prose(page.read_text(encoding='utf-8'))):
        if re.match(r'[a-z][a-z0-9+.-]*:', target) or target.startswith('//'):
            continue  # http:, https:, mailto:
        path, _, anchor = target.partition('#')
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f'{target} (no such file: {dest})')
        elif anchor and dest.suffix == '.md' and anchor not in anchors(dest):
            broken.append(f'{target} (no heading #{anchor} in {dest.name})')
    assert not broken, f'{name(page)}: broken links: {broken}'


def case_clashes(root: Path) -> list:
    """Return the groups of paths under ``root`` that differ only in case."""
    seen = {}
    for path in sorted(root.rglob('*')):
        rel = path.relative_to(root).as_posix()
        seen.setdefault(rel.lower(), []).append(rel)
    return [paths for paths in seen.values() if len(paths) > 1]


def test_no_two_files_under_docs_differ_only_in_case(tmp_path):
    """The file systems of macOS and Windows ignore case: such paths would be one file there."""
    (tmp_path / 'results').mkdir()
    for rel in ('line.md', 'LINE.md', 'results/line.md', 'Results/x.md'):
        (tmp_path / rel).parent.mkdir(exist_ok=True)
        (tmp_path / rel).write_text('')
    assert case_clashes(tmp_path) == [['LINE.md', 'line.md'], ['Results', 'results']]
    clashes = case_clashes(ROOT / 'docs')
    assert not clashes, f'paths under docs/ that differ only in case: {clashes}'


@pytest.mark.parametrize('page', pages(), ids=name)
def test_no_history_in_hand_written_docs(page):
    """No commit hashes and no issue numbers: history belongs in the git log.

    The generated pages' notes written by hand too: only their generated blocks are skipped.
    """
    text = without_generated(page.read_text(encoding='utf-8'))
    hashes = HASH.findall(text)
    issues = ISSUE.findall(text)
    assert not hashes, f'{name(page)}: commit hashes {hashes}'
    assert not issues, f'{name(page)}: issue references {issues}'


def test_every_hand_written_doc_is_linked_from_the_readme():
    """A newcomer finds every page of docs/ from the README."""
    linked = {(ROOT / t.partition('#')[0]).resolve()
              for t in LINK.findall(prose(README.read_text(encoding='utf-8')))}
    missing = [name(p) for p in DOCS if p.resolve() not in linked]
    assert not missing, f'docs not linked from README.md: {missing}'


def script_options():
    """Return every ``--option`` the scripts and the launcher define."""
    sources = [ROOT / 'scara_collab' / 'run' / 'options.py', *sorted(
        (ROOT / 'scripts').glob('*.py')), *sorted((ROOT / 'scripts').iterdir())]
    found = set()
    for path in sources:
        if path.is_file():
            found |= set(re.findall(r"""['"](--[a-z][a-z0-9-]*)['"]""", path.read_text()))
    return found


def named_options(text: str):
    """Return the ``--options`` given to the launcher, the demo or a benchmark in ``text``."""
    out = set()
    for line in re.findall(r'scripts/[\w.]+[^\n`|#]*', text):
        out |= set(re.findall(r'(?<![\w-])--[a-z][a-z0-9-]*', line))
    for cell in re.findall(r'^\| (`--[^|]*(?:\\\|[^|]*)*)\|', text, re.M):  # an options table
        out |= set(re.findall(r'(?<![\w-])--[a-z][a-z0-9-]*', cell))
    return out


@pytest.mark.parametrize('page', [p for p in pages() if GENERATED not in p.parents],
                         ids=name)
def test_every_option_named_exists(page):
    """An option the docs tell a user to pass is one the launcher or a script defines."""
    unknown = named_options(page.read_text(encoding='utf-8')) - script_options() \
        - FOREIGN_OPTIONS
    assert not unknown, f'{name(page)} names options no script defines: {sorted(unknown)}'


def test_readme_names_every_launch_mode_and_lockstep():
    """The README's launcher section names each mode of the graph and both lockstep values."""
    from scara_collab import graph
    text = README.read_text(encoding='utf-8')
    for mode in graph.LAUNCH_MODES:
        assert f'`{mode}`' in text, mode
    assert '--lockstep on|off' in text.replace('\\|', '|')
