"""ament_flake8's rules (99 columns, single quotes, Google import order, pep257) on all code."""
from pathlib import Path
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]


def test_flake8_is_clean():
    """flake8 with ament's rules: nothing in the package, benchmarks, tests, launch, scripts."""
    targets = ['scara_collab', 'benchmarks', 'test', 'launch', 'setup.py'] + [
        str(p.relative_to(ROOT)) for p in (ROOT / 'scripts').glob('*.py')]
    proc = subprocess.run([sys.executable, '-m', 'flake8', *targets], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f'flake8 found problems:\n{proc.stdout}{proc.stderr}'
