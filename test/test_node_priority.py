"""
The stepping thread under the kernel's real-time policy (`stepping_priority`), on the real kernel.

Granted (root or an RLIMIT_RTPRIO allowing it): exactly the stepping thread of the node runs
SCHED_FIFO at the asked priority, read from /proc, and the diagnostics say so. Refused: the
reason and the remedy, and normal scheduling.
"""
import os
import resource

import pytest
from diagnostic_msgs.msg import DiagnosticArray

from node_harness import (NodeProcess, diagnostics_values, next_domain_id, run_python,
                          thread_stats)

SCHED_FIFO = 1
PRIORITY = 7


def thread_policies(pid: int) -> list[tuple[str, int, int]]:
    """(name, policy, real-time priority) of every thread of process ``pid``."""
    return [(name, int(fields[38]), int(fields[37]))  # fields 41 and 40 of proc(5)
            for name, fields in thread_stats(pid)]


def _may_use_fifo(priority: int) -> bool:
    return os.geteuid() == 0 or resource.getrlimit(resource.RLIMIT_RTPRIO)[0] >= priority


@pytest.mark.skipif(not _may_use_fifo(PRIORITY), reason="this user may not use SCHED_FIFO "
                    "(the refused branch is tested below)")
def test_a_granted_priority_puts_exactly_the_stepping_thread_under_sched_fifo(
        tmp_path, peer_and_domain):
    peer, domain = peer_and_domain
    node = NodeProcess(tmp_path / "node", domain, dict(
        time_mode="realtime", publish_rate=200.0, record=False, stepping_priority=PRIORITY,
        wake_spin=1e-4))
    peer.watch = node
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.spin_until(lambda: peer.received.get("/diagnostics"), 30.0, "diagnostics")
        values = diagnostics_values(peer.last("/diagnostics"))
        policies = thread_policies(node.proc.pid)
        fifo = [p for p in policies if p[1] == SCHED_FIFO]
        assert [p[2] for p in fifo] == [PRIORITY], policies  # one thread, at the priority
        assert values["stepping_priority"] == str(PRIORITY)
        assert all(p[2] == 0 for p in policies if p[1] != SCHED_FIFO)
    finally:
        rc = node.stop()
    assert rc == 0, node.stderr


def test_fast_mode_ignores_the_priority(tmp_path, peer_and_domain):
    """Fast mode never sleeps: it would be throttled, so the policy applies in real time only."""
    peer, domain = peer_and_domain
    node = NodeProcess(tmp_path / "node", domain, dict(
        time_mode="fast", publish_rate=200.0, record=False, stepping_priority=PRIORITY))
    peer.watch = node
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.spin_until(lambda: peer.received.get("/diagnostics"), 30.0, "diagnostics")
        assert diagnostics_values(peer.last("/diagnostics"))["stepping_priority"] == "0"
        assert all(p[1] != SCHED_FIFO for p in thread_policies(node.proc.pid))
    finally:
        rc = node.stop()
    assert rc == 0, node.stderr


def test_a_spin_of_the_whole_period_is_refused_at_start_up_naming_both_parameters(tmp_path):
    node = NodeProcess(tmp_path / "node", next_domain_id(), dict(
        time_mode="realtime", record=False, stepping_priority=PRIORITY, wake_spin=1e-3))
    assert node.wait(60) != 0
    assert "stepping_priority 7 (SCHED_FIFO)" in node.stderr
    assert "wake_spin must be at most 0.0005 s" in node.stderr
    assert "Traceback" not in node.stderr


REFUSED = r"""
import os, resource, sys
from flexure_sim.node.stage.pacing import set_thread_fifo
resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
if os.geteuid() == 0:
    os.setgid(65534); os.setuid(65534)      # no longer root: no CAP_SYS_NICE
priority, why = set_thread_fifo(7)
print(why)
sys.exit(0 if priority == 0 and os.sched_getscheduler(0) == os.SCHED_OTHER else 3)
"""


def test_a_refused_priority_says_why_and_how_to_allow_it():
    out = run_python(REFUSED)
    assert out.returncode == 0, out.stdout + out.stderr
    why = out.stdout.strip()
    assert why.startswith("stepping_priority 7 (SCHED_FIFO) refused (Operation not permitted)")
    assert "RLIMIT_RTPRIO of at least 7" in why and "'<user> - rtprio 7'" in why
