"""The CPU wake-up latency request (`node.cpu_latency`), against the real kernel's PM QoS."""
import os

import pytest

from flexure_sim.node.stage.cpu_latency import DEVICE, latency_in_effect, request_cpu_latency

from node_harness import run_python

pytestmark = pytest.mark.skipif(not os.path.exists(DEVICE),
                                reason=f"{DEVICE}: this kernel has no PM QoS device")


@pytest.mark.skipif(not os.access(DEVICE, os.W_OK), reason=f"{DEVICE} is not writable here "
                    "(the refused branch is tested below)")
def test_a_granted_request_is_in_effect_while_held_and_withdrawn_on_release():
    before = latency_in_effect()
    assert before is not None and before > 7  # nobody else holds a limit this low
    request, why = request_cpu_latency(7)
    assert why == "" and request is not None and request.held
    try:
        assert latency_in_effect() == 7  # the kernel's aggregate limit is ours
    finally:
        request.release()
    request.release()  # idempotent
    assert not request.held
    assert latency_in_effect() == before


REFUSED = r"""
import os, sys
from flexure_sim.node.stage.cpu_latency import request_cpu_latency
if os.geteuid() == 0:
    os.setgid(65534); os.setuid(65534)      # no longer root: the device is root's, mode 0600
request, why = request_cpu_latency(0)
print(why)
sys.exit(0 if request is None else 3)
"""


@pytest.mark.skipif(os.stat(DEVICE).st_mode & 0o006 if os.path.exists(DEVICE) else True,
                    reason=f"{DEVICE} is writable by everyone here")
def test_a_refused_request_says_why_and_how_to_allow_it():
    out = run_python(REFUSED)
    assert out.returncode == 0, out.stdout + out.stderr
    why = out.stdout.strip()
    assert why.startswith("cpu_latency_us 0 refused (Permission denied: /dev/cpu_dma_latency)")
    assert "udev rule" in why


def test_a_missing_device_is_named():
    request, why = request_cpu_latency(0, device="/nonexistent/cpu_dma_latency")
    assert request is None
    assert why == ("cpu_latency_us 0 not requested: /nonexistent/cpu_dma_latency does not exist "
                   "(a Linux kernel with PM QoS has it)")
