"""Docstring style as ROS 2 packages check it: ament_pep257 with its default ('ament') rules."""

from pathlib import Path

from ament_pep257.main import main
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    """Run ament_pep257 over the package and its tests; it prints every problem it finds."""
    rc = main(argv=[str(ROOT / "flexure_sim"), str(ROOT / "test")])
    assert rc == 0, "docstring style problems (listed above)"
