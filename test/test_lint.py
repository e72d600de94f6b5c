"""ROS 2's linters over the package: ament_flake8 and ament_pep257 (colcon test runs them too)."""

from pathlib import Path

from ament_flake8.main import main_with_errors
from ament_pep257.main import main as pep257_main
import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = [str(ROOT / 'cvc_balance'), str(ROOT / 'test'), str(ROOT / 'benchmarks'),
           str(ROOT / 'setup.py'), str(ROOT / 'docs' / 'conf.py'), str(ROOT / 'docs' / '_ext'),
           str(ROOT / 'docs' / 'pictures.py')]


@pytest.mark.linter
def test_lint_flake8():
    rc, errors = main_with_errors(argv=SOURCES)
    assert rc == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)


@pytest.mark.linter
def test_lint_pep257():
    rc = pep257_main(argv=SOURCES)
    assert rc == 0, 'Found docstring style errors'
