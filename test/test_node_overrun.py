"""
One WARN line when real-time ticks do not fit their period (node/stage/overrun.py).

The rule on a clock the test drives (more than 1 % of a second's ticks missed; at most one line
per 10 s), then a real stage node overloaded on purpose: 10 kHz ticks of 200 engine steps each,
several times the 100 us period on any machine, must say so once, with its measured tick work,
the period and the remedies.
"""
from __future__ import annotations

import re
import signal
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray

from flexure_sim.node.stage.overrun import OverrunWatch
from node_harness import NodeProcess, Peer, next_domain_id

PERIOD = 1e-3
SETTINGS = "publish_rate 1000 Hz, monitor_rate 0 Hz, stepping_priority 0"


def run_seconds(watch: OverrunWatch, start: float, seconds: int, missed_per_second: int,
                work: float = 4e-4) -> list[tuple[float, str]]:
    """Feed ``seconds`` of 1 kHz ticks, ``missed_per_second`` of each second's missed."""
    lines = []
    ticks = round(1.0 / PERIOD)
    for s in range(seconds):
        for k in range(ticks):
            now = start + s + (k + 1) * PERIOD
            line = watch.tick(now, work, k < missed_per_second, SETTINGS)
            if line is not None:
                lines.append((now, line))
    return lines


def test_a_second_over_one_percent_warns_once_then_not_for_ten_seconds():
    watch = OverrunWatch(PERIOD, 0.0)
    # 1 % missed is within the rule; 2 % is not.
    assert run_seconds(watch, 0.0, 3, missed_per_second=10) == []
    lines = run_seconds(watch, 3.0, 30, missed_per_second=20)
    times = [t for t, _ in lines]
    assert len(times) == 3
    assert times[0] == 4.0  # at the end of the first second over the limit
    assert all(b - a >= 10.0 for a, b in zip(times, times[1:]))
    first, second = lines[0][1], lines[1][1]
    assert "20 of 1000 ticks (2.0 %) missed in the last second" in first
    assert "since the last such warning" not in first
    assert "over 1 % in 10 seconds since" in second  # the seconds it stayed quiet about
    assert "400 us on average, 400 us at most, of the 1000 us period" in first
    for remedy in ("publish_rate", "monitor_rate", "stepping_priority"):
        assert remedy in first
    assert first.endswith(SETTINGS)
    assert watch.warnings == 3


def test_a_new_period_starts_a_new_window():
    watch = OverrunWatch(PERIOD, 0.0)
    assert run_seconds(watch, 0.0, 1, missed_per_second=0) == []
    watch.set_period(2 * PERIOD, 1.0)
    assert watch.tick(1.5, 1e-3, True, SETTINGS) is None
    line = watch.tick(2.0, 3e-3, True, SETTINGS)
    assert line is not None and "2 of 2 ticks" in line and "of the 2000 us period" in line


@pytest.mark.slow
def test_an_overloaded_node_warns_once_naming_its_tick_work_and_the_remedies(tmp_path):
    domain = next_domain_id()
    node = NodeProcess(tmp_path / "node", domain, {
        "mechanism": "microstage", "time_mode": "realtime", "publish_rate": 10000.0,
        "sim_step": 5e-7, "record": False})
    peer = Peer(domain)
    peer.watch = node
    try:
        line = node.wait_for_output("missed in the last second", timeout=120)
        warned = time.monotonic()
        assert "[WARN]" in line
        work = re.search(r"takes (\d+) us on average, (\d+) us at most, of the 100 us period",
                         line)
        assert work, line
        assert int(work.group(1)) > 100  # 200 steps a tick: more than the period
        assert "now publish_rate 10000 Hz, monitor_rate 0 Hz, stepping_priority 0" in line
        # Still overloaded (its diagnostics go on counting missed ticks) for a further 4 s of
        # wall time: no second line, the next one is due 10 s after the first at the earliest.
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.spin_until(lambda: time.monotonic() > warned + 4.0
                        and len(peer.received["/diagnostics"]) >= 2, 60,
                        "4 s of overloaded diagnostics")
    finally:
        rc = node.stop(signal.SIGINT)
        peer.close()
    assert rc == 0, node.stderr
    assert node.stderr.count("missed in the last second") == 1, node.stderr
