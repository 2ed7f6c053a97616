"""
A stage_node process that cannot release its middleware at exit ends anyway.

Releasing a node can hang in the middleware (``stage_node.exit_deadline``: Fast DDS spinning
in ``DomainParticipant::set_listener`` while it holds the GIL). The deadline is a C thread
(faulthandler's), so it ends even a process whose main thread never gives the GIL back: a
foreign call made through ``ctypes.PyDLL``, which keeps the GIL, to ``pause(2)``.
"""
from __future__ import annotations

import subprocess
import sys
import time

from conftest import ROOT

HANG = """
import ctypes, sys
from flexure_sim.node.stage.stage_node import exit_deadline
print("stage_node: error: the reason, said first", file=sys.stderr, flush=True)
with exit_deadline({seconds}):
    {block}
print("released", flush=True)
"""


def _run(block: str, seconds: float = 1.0) -> tuple[subprocess.CompletedProcess, float]:
    start = time.monotonic()
    done = subprocess.run([sys.executable, "-c", HANG.format(seconds=seconds, block=block)],
                          cwd=ROOT, capture_output=True, text=True, timeout=60,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    return done, time.monotonic() - start


def test_a_release_that_holds_the_gil_forever_ends_the_process_at_the_deadline():
    done, took = _run("ctypes.PyDLL(None).pause()")
    assert done.returncode == 1, (done.returncode, done.stderr)
    assert 1.0 <= took < 30.0, took
    assert "released" not in done.stdout
    lines = done.stderr.splitlines()
    assert lines[0] == "stage_node: error: the reason, said first"
    assert "Timeout (0:00:01)!" in done.stderr  # faulthandler's stacks follow the reason
    assert "exit_deadline" not in lines[0]


def test_a_release_in_time_goes_on_and_the_deadline_is_cancelled():
    done, _ = _run("import time; time.sleep(0.1)")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "released"
    # Cancelled: a process that lives on past the deadline is not ended by it.
    done, _ = _run("pass\nimport time; time.sleep(2.0)", seconds=0.5)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "released"
