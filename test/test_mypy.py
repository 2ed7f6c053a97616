"""Static types of the engine: ``python -m mypy flexure_sim/engine`` finds no error."""

from pathlib import Path
import subprocess
import sys

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.linter
@pytest.mark.slow  # a cold cache takes ~10 s; a warm one (.mypy_cache) under 1 s
def test_mypy_finds_no_error_in_the_engine():
    """Run mypy with the project's configuration (setup.cfg [mypy]) over flexure_sim/engine."""
    p = subprocess.run([sys.executable, "-m", "mypy", "flexure_sim/engine"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    report = p.stdout + p.stderr
    print(report)
    assert "No module named mypy" not in report, "mypy is not installed (requirements.txt)"
    assert p.returncode == 0, f"mypy found type errors in flexure_sim/engine:\n{report}"
    assert report.startswith("Success: no issues found in"), report
