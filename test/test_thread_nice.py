"""Per-thread niceness of the stepping loop (`pacing.set_thread_nice`), on the real kernel."""
import os
import subprocess
import sys
import threading

import pytest

from flexure_sim.node.stage.pacing import set_thread_nice

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="per-thread niceness is Linux only"
)


def test_a_thread_gets_its_own_niceness_and_the_others_keep_theirs():
    before = os.getpriority(os.PRIO_PROCESS, 0)
    target = min(before + 5, 19)  # raising niceness is always permitted
    seen = {}

    def body():
        seen["result"] = set_thread_nice(target)
        seen["kernel"] = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    assert seen["result"] == (target, "")
    assert seen["kernel"] == target
    assert os.getpriority(os.PRIO_PROCESS, 0) == before  # this (main) thread is untouched


REFUSED = r"""
import os, resource, sys
from flexure_sim.node.stage.pacing import set_thread_nice
soft, hard = resource.getrlimit(resource.RLIMIT_NICE)
resource.setrlimit(resource.RLIMIT_NICE, (0, hard))   # no lowering allowed by the limit
if os.geteuid() == 0:
    os.setgid(65534); os.setuid(65534)                 # and no CAP_SYS_NICE either
nice, why = set_thread_nice(-10)
print(nice, "|", why)
sys.exit(0 if nice == os.getpriority(os.PRIO_PROCESS, 0) else 3)
"""


def test_a_refused_request_keeps_the_niceness_and_says_how_to_allow_it():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, "-c", REFUSED], capture_output=True, text=True, env=env,
                         cwd="/", timeout=60)
    assert out.returncode == 0, out.stderr
    nice, why = out.stdout.strip().split(" | ")
    assert "niceness -10 refused" in why and "RLIMIT_NICE of at least 30" in why
    assert f"keeps {nice}" in why
