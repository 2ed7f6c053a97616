"""
How stage_node ends when C code is in the way (real subprocesses, no node needed).

- Releasing a node can hang in the middleware (``node/release.py``, ``exit_deadline``: Fast
  DDS spinning in ``DomainParticipant::set_listener`` while it holds the GIL). The deadline
  is a C thread (faulthandler's), so it ends even a process whose main thread never gives the
  GIL back: a foreign call made through ``ctypes.PyDLL``, which keeps the GIL, to ``pause(2)``.
- A start-up signal that lands in a Python function C calls back (llvmlite's object-cache
  hook, while Numba compiles) is sent again and stops start-up after it (``SignalGuard``).
"""
from __future__ import annotations

import subprocess
import sys

from conftest import ROOT

HANG = """
import ctypes, sys
from flexure_sim.node.release import exit_deadline
print("stage_node: error: the reason, said first", file=sys.stderr, flush=True)
with exit_deadline({seconds}):
    {block}
print("released", flush=True)
"""


def _run(block: str, seconds: float = 1.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", HANG.format(seconds=seconds, block=block)],
                          cwd=ROOT, capture_output=True, text=True, timeout=60,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})


def test_a_release_that_holds_the_gil_forever_ends_the_process_at_the_deadline():
    done = _run("ctypes.PyDLL(None).pause()")
    assert done.returncode == 1, (done.returncode, done.stderr)
    assert "released" not in done.stdout
    lines = done.stderr.splitlines()
    assert lines[0] == "stage_node: error: the reason, said first"
    assert "Timeout (0:00:01)!" in done.stderr  # the 1 s deadline ended it; stacks follow
    assert "exit_deadline" not in lines[0]


def test_a_release_in_time_goes_on_and_the_deadline_is_cancelled():
    done = _run("import time; time.sleep(0.1)", seconds=30.0)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "released"
    # Cancelled: a process that lives on past the deadline is not ended by it.
    done = _run("pass\nimport time; time.sleep(2.0)", seconds=0.5)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "released"


CALLBACK = """
import ctypes, os, signal, sys, time
from flexure_sim.node.stage.stage_node import Interrupted, SignalGuard
guard = SignalGuard()
guard.install()

def _raw_object_cache_notify():  # as llvmlite's hook, called from C through ctypes
    os.kill(os.getpid(), signal.SIGINT)
    end = time.monotonic() + 0.2
    while time.monotonic() < end:  # the handler runs here, within the callback
        pass

hook = ctypes.CFUNCTYPE(None)(_raw_object_cache_notify)
try:
    hook()
    end = time.monotonic() + 10.0
    while time.monotonic() < end:  # Python code that can take the exception
        pass
    print("not interrupted")
except Interrupted as exc:
    print("interrupted after the callback by signal", exc.signum, guard.received)
"""


def test_a_signal_during_start_up_that_lands_in_a_c_callback_stops_start_up_after_it():
    """
    A start-up signal landing in a C callback raises in the Python code after it.

    Ctrl-C while Numba compiles (a fresh install's first start) can land in llvmlite's
    object-cache hook, a Python function C calls through ctypes, where an exception is printed
    ("Exception ignored ...", a traceback) and lost. The guard sends the signal again.
    """
    done = subprocess.run([sys.executable, "-c", CALLBACK], cwd=ROOT, capture_output=True,
                          text=True, timeout=60,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "interrupted after the callback by signal 2 2", done.stdout
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr
