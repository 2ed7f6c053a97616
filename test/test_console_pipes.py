"""
Every console script into a closed pipe (`... | head -1`): quiet, as Unix tools are.

The installed scripts (the package's ``console_scripts`` entry points, in the environment's
bin folder) run as real subprocesses whose stdout is a pipe with no reader: the first write
fails. A Unix tool is stopped by SIGPIPE there without a word and its shell reports 141;
ours must say nothing either and exit with 141 (flexure_sim/console.py).
"""
from __future__ import annotations

import os
import subprocess
import sys
from importlib.metadata import distribution
from pathlib import Path

import pytest

from conftest import ROOT

#: Every test here runs the command line in subprocesses (seconds each).
pytestmark = pytest.mark.slow

BIN = Path(sys.executable).parent
SCRIPTS = sorted(ep.name for ep in distribution("flexure_sim").entry_points
                 if ep.group == "console_scripts")
PIPE_CLOSED = 128 + 13


def _into_closed_pipe(*argv: str) -> subprocess.CompletedProcess:
    read, write = os.pipe()
    os.close(read)  # nobody will ever read: the first write to stdout fails with EPIPE
    try:
        return subprocess.run([str(BIN / argv[0]), *argv[1:]], stdout=write,
                              stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
                              cwd=ROOT, timeout=120)
    finally:
        os.close(write)


def test_every_console_script_is_covered():
    assert set(SCRIPTS) == {"flexure-sim", "pi_controller", "replay", "stage_node"}


@pytest.mark.parametrize("script", SCRIPTS)
def test_help_into_a_closed_pipe_exits_quietly(script):
    p = _into_closed_pipe(script, "--help")
    assert (p.returncode, p.stderr) == (PIPE_CLOSED, "")


def test_help_into_an_open_pipe_is_unchanged():
    for script in SCRIPTS:
        p = subprocess.run([str(BIN / script), "--help"], capture_output=True, text=True,
                           stdin=subprocess.DEVNULL, timeout=120)
        assert p.returncode == 0 and p.stderr == "" and "usage: " in p.stdout, (script, p)


def test_an_analysis_into_a_closed_pipe_exits_quietly():
    p = _into_closed_pipe("flexure-sim", "modes", "xy_stage")
    assert (p.returncode, p.stderr) == (PIPE_CLOSED, "")
    p = _into_closed_pipe("flexure-sim", "simulate", "microstage", "--static", "--json")
    assert (p.returncode, p.stderr) == (PIPE_CLOSED, "")


def test_head_takes_the_first_line_and_nothing_is_reported():
    """The issue's command line, through a shell: `flexure-sim modes xy_stage | head -1`."""
    p = subprocess.run(["bash", "-c", f"'{BIN / 'flexure-sim'}' modes xy_stage | head -1; "
                        "echo \"status ${PIPESTATUS[0]}\" >&2"],
                       capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert p.stdout.startswith("mechanism: xy_stage") and p.stdout.count("\n") == 1
    # Whether the command wrote before or after head exited is a race: 0 or 141, never noise.
    assert p.stderr in ("status 0\n", f"status {PIPE_CLOSED}\n"), p.stderr
