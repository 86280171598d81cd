"""The solver section runs alone (``--only solvers --smoke``) and times the one formula."""
import json
from pathlib import Path
import subprocess
import sys

from benchmarks.util import FIGURES, RESULTS_PAGE

ROOT = Path(__file__).resolve().parents[1]


def test_the_solver_section_runs_alone_and_compares_the_collision_formula(tmp_path):
    """``benchmark.py --smoke --only solvers`` writes its block, its figure and its rows.

    The collision row sets the one formula's single-pair time beside the branchy float
    formula's, and both give the same distances.
    """
    proc = subprocess.run([sys.executable, str(ROOT / 'scripts' / 'benchmark.py'), '--smoke',
                           '--only', 'solvers', '--out', str(tmp_path), '--json',
                           str(tmp_path / 'results.json')],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = {r['what']: r for r in json.loads((tmp_path / 'results.json').read_text())
            ['solvers']['rows']}
    one = rows['capsule distances, one state pair (the one formula)']
    assert one['ours'] > 0 and one['reference'] > 0 and 'max diff' in one['note']
    assert float(one['note'].split()[-2]) <= 1e-15
    page = (tmp_path / RESULTS_PAGE).read_text()
    assert '<!-- benchmark:solvers:begin -->' in page and '<!-- benchmark:paths:' not in page
    assert (tmp_path / FIGURES / 'solvers.png').is_file()


def test_the_foresight_study_executes_its_conflicts_at_full_size(tmp_path):
    """All 200 pairs drawn and the first 30 conflicts executed in physics, none refused.

    Both arms are put at their starts before either move is sent: the simulator's door checks
    a move against where the other arm stands, which is the previous pair's end otherwise.
    """
    from benchmarks import foresight
    result = foresight.measure(False, tmp_path)
    executed = [p['executed_min_m'] for p in result['pairs'] if p['executed_min_m'] is not None]
    assert result['n_pairs'] == 200 and len(executed) == 30
    assert min(executed) >= result['margin']
