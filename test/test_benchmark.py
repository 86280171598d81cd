"""The one-command benchmark runs (smoke sizes) and writes every section, figure and claim."""
import json
from pathlib import Path
import re
import subprocess
import sys

import pytest

from benchmarks import results_page
from benchmarks.claims import CLAIMS
from benchmarks.results_page import SECTIONS, SUMMARY_ORDER
from benchmarks.util import FIGURES, fmt_seconds, RESULTS_PAGE, spread, table, write_block

ROOT = Path(__file__).resolve().parents[1]
#: the design documents' sentences the claims quote, kept word for word (the documents are not
#: part of the repository)
QUOTED = Path(__file__).resolve().parent / 'design_document_quotes.txt'
#: a quote on the results page: ``> the quote — *its source*``
QUOTE_LINE = re.compile(r'^> (.+) — \*(.+)\*$', re.M)


@pytest.fixture(scope='module')
def smoke(tmp_path_factory):
    """Run ``benchmark.py --smoke`` once; return its folder, process and parsed results."""
    out = tmp_path_factory.mktemp('bench')
    proc = subprocess.run(
        [sys.executable, str(ROOT / 'scripts' / 'benchmark.py'), '--smoke', '--out', str(out),
         '--json', str(out / 'results.json')],
        capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stdout + proc.stderr[-3000:]
    return out, proc, json.loads((out / 'results.json').read_text())


def _sections(text):
    """Return {title: body} of the ``## `` sections of a Markdown text."""
    parts = re.split(r'^## (.+)$', text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2]))


def test_every_section_reports_progress_with_elapsed_time(smoke):
    """Every benchmark section prints its progress line with the elapsed time on stderr."""
    _, proc, _ = smoke
    for section in SECTIONS:
        title = re.escape(section.title)
        assert re.search(rf'^\[\s*\d+\.\d s\] {title} done in \d+\.\d s$',
                         proc.stderr, re.M), f'no progress line for {section.title!r}'


def test_the_results_page_has_every_section_with_the_claims_beside(smoke):
    """The results page has every section, none failed, each with its claims quoted."""
    out, _, _ = smoke
    text = (out / RESULTS_PAGE).read_text()
    sections = _sections(text)
    assert 'Summary' in sections
    for title in results_page.headings():
        assert title in sections, f'section {title!r} missing'
        body = sections[title]
        assert 'This section failed' not in body, body[:300]
        assert "design documents' claim" in body, f'{title}: no claim column'
        assert QUOTE_LINE.search(body), f'{title}: no quoted claim'
    assert 'smoke run' in text and 'Machine:' in text


def test_figures_exist_are_small_pngs_and_are_linked(smoke):
    """Every figure is a PNG of 5-200 kB, and the results page links it."""
    out, _, results = smoke
    text = (out / RESULTS_PAGE).read_text()
    for key in (s.key for s in SECTIONS):
        png = out / FIGURES / f'{key}.png'
        assert png.is_file(), f'{png} missing ({results["figures"].get(key)})'
        data = png.read_bytes()
        assert data[:8] == b'\x89PNG\r\n\x1a\n'
        assert 5_000 < len(data) < 200_000
        assert f']({FIGURES}/{key}.png)' in text


def test_numbers_come_from_the_run(smoke):
    """The numbers on the results page are those of the run, and they are plausible.

    IK latency, line and joint deviations, throughput, mirror error, singularity and foresight.
    """
    out, _, results = smoke
    text = (out / RESULTS_PAGE).read_text()
    ik = next(r for r in results['solvers']['rows'] if r['what'] == 'IK, one target')
    assert ik['ours'] > 0 and ik['reference'] > 0
    assert fmt_seconds(ik['ours']) in text
    paths = results['paths']
    assert paths['planned']['line']['max_deviation'] < 1e-6
    assert 0.05 < paths['planned']['joint']['max_deviation'] < 1.0
    assert paths['executed']['line']['max_deviation'] < 5e-3
    assert f'{paths["planned"]["joint"]["max_deviation"]:.3g} m' in text
    jobs = results['throughput']['runs']
    assert jobs and all(r['sim_seconds'] >= results['throughput']['duration'] for r in jobs)
    sync = results['sync']
    assert sync['moves'] and sync['mirror_error_max_m'] < 0.01
    sing = {c['name']: c for c in results['singularity']['cases']}
    radial = sing['outer circle, radial approach to 2.5 m']
    assert radial['pinv']['peak_speed'] > radial['dls']['peak_speed']
    pairs = results['foresight']['pairs']
    assert len(pairs) == results['foresight']['n_pairs']
    for p in pairs:
        if p['conflict']:
            assert p['foresight_s'] >= results['foresight']['lead']


def test_a_run_replaces_only_its_blocks_of_the_page(tmp_path, smoke):
    """A section's block replaces its old text; hand-written text and other blocks stay.

    A page without markers has the text under each heading replaced; the next run finds the
    markers.
    """
    _, _, results = smoke
    page = ('# Results, measured\n\nold run\n\n## Summary\n\nold table\n\n'
            '## 1. Path deviation: straight line vs joint interpolation\n\nold paths\n\n'
            '## Notes\n\nhand-written\n\n<!-- faults:begin -->\nfaults\n<!-- faults:end -->\n')
    only_paths = dict(results, **{s.key: {'skipped': True} for s in SECTIONS[1:]})
    text = results_page.render(only_paths, page)
    assert 'old paths' not in text and 'old run' not in text
    assert '<!-- benchmark:paths:begin -->' in text and '<!-- benchmark:solvers:' not in text
    assert 'hand-written' in text and '<!-- faults:begin -->\nfaults\n' in text
    again = results_page.render(results, text)
    sections = _sections(again)
    assert again.count('<!-- benchmark:paths:begin -->') == 1
    assert '| IK latency |' in sections['Summary'] and 'hand-written' in sections['Notes']
    written = tmp_path / RESULTS_PAGE
    write_block(written, 'soak', 'Soak', 'first')
    write_block(written, 'soak', 'Soak', 'second')
    assert written.read_text() == ('# Results, measured\n\n## Soak\n\n<!-- soak:begin -->\n'
                                   'second\n<!-- soak:end -->\n')


def test_sections_are_registered_once_each():
    """Each section has its own key; the summary names each at most once."""
    keys = [s.key for s in SECTIONS]
    assert len(set(keys)) == len(keys)
    assert len(set(SUMMARY_ORDER)) == len(SUMMARY_ORDER) and set(SUMMARY_ORDER) <= set(keys)


def test_render_reports_a_failed_section_and_keeps_a_skipped_ones_block(smoke):
    """A failed section shows its error; a skipped one keeps its block; other blocks stay."""
    out, _, results = smoke
    previous = (out / RESULTS_PAGE).read_text()
    results = dict(results, paths={'error': 'RuntimeError: boom'}, solvers={'skipped': True})
    sections = _sections(results_page.render(results, previous))
    first, second = results_page.headings()[:2]
    assert '**This section failed:** `RuntimeError: boom`' in sections[first]
    assert sections[second] == _sections(previous)[second]


def test_helpers():
    """``fmt_seconds``, ``spread`` and ``md_table`` format as documented."""
    assert fmt_seconds(3.5e-6) == '3.5 µs' and fmt_seconds(0.0147) == '14.7 ms'
    s = spread([1.0, 2.0, 3.0, None, float('nan')])
    assert s['n'] == 3 and s['mean'] == 2.0 and s['std'] == 1.0
    assert table([{'a': 1, 'b': 2}], 'lr') == '| a | b |\n|---|---:|\n| 1 | 2 |'


def quoted() -> dict:
    """Return the design documents' sentences kept in the repository: ``{key: (source, text)}``."""
    blocks = {}
    for block in QUOTED.read_text(encoding='utf-8').split('\n== ')[1:]:
        head, _, text = block.partition('\n')
        key, _, source = head.partition(': ')
        blocks[key] = (source, text)
    return blocks


def test_every_claim_has_its_sentences_kept_with_the_same_source():
    """Each claim names the document and section its kept sentences come from."""
    kept = quoted()
    assert set(kept) == set(CLAIMS)
    for key, claim in CLAIMS.items():
        assert kept[key][0] == claim.source, key


@pytest.mark.parametrize('key', ['ik_latency', 'solver_latency', 'mirror_error', 'lag',
                                 'foresight', 'collision_risk', 'throughput', 'path_length',
                                 'joint_deviation'])
def test_sentence_claims_are_verbatim_quotes(key):
    """Each sentence claim is word for word in the design documents' sentences kept here."""
    assert CLAIMS[key].quote in quoted()[key][1]


def test_the_page_quotes_only_the_claims_with_their_sources(smoke):
    """Every quote on the results page is a claim's quote, cited with that claim's source."""
    out, _, _ = smoke
    quotes = QUOTE_LINE.findall((out / RESULTS_PAGE).read_text())
    assert quotes
    known = {(c.quote, c.source) for c in CLAIMS.values()}
    assert not [q for q in quotes if q not in known]
