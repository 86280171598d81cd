"""The core benchmark runs (quick mode) and measures what it claims to measure."""
from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]


def test_bench_core_quick_run(tmp_path):
    """``bench_core.py --quick`` runs, compares with Pinocchio and writes its JSON rows.

    The planned line deviation meets its target.
    """
    out = tmp_path / 'bench.json'
    proc = subprocess.run([sys.executable, str(ROOT / 'scripts' / 'bench_core.py'), '--quick',
                           '--json', str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert 'IK, one target' in proc.stdout and 'Pinocchio' in proc.stdout
    import json
    rows = {r['what']: r for r in json.loads(out.read_text())['rows']}
    assert rows['line deviation (planned)']['met'] is True
    assert float(rows['IK, one target']['ours'].split()[0]) > 0
