"""Code style as ROS 2 packages check it: ament_flake8 (pycodestyle + pyflakes, 99 columns)."""

from pathlib import Path

from ament_flake8.main import main_with_errors
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    """
    Run ament_flake8 with its own configuration over the package, its tests and setup.py.

    The flake8 plugins a Jazzy install adds (quotes, import order, builtins) are not on PyPI
    and are not checked here.
    """
    paths = [str(ROOT / name) for name in ("flexure_sim", "test", "setup.py")]
    rc, errors = main_with_errors(argv=paths)
    assert rc == 0, f"{len(errors)} code style errors:\n" + "\n".join(errors)
