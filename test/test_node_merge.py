"""
Real time after a stall: stage_node as a real subprocess, stopped and continued with signals.

With ``merge_late_ticks``, a loop that falls behind merges the ticks it is late for into one
(`pacing.Pacer`): the engine steps through their periods, simulated time stays with wall time,
and every merged tick is reported (``merged_ticks``, counted in ``missed_ticks``) and absent
from the topics and the recording, whose stamps stay on the tick grid.
"""
from __future__ import annotations

import signal
import time

from diagnostic_msgs.msg import DiagnosticArray

from flexure_sim.recording import read_log

from node_harness import NodeProcess, Peer, diagnostics_values, next_domain_id

RATE = 200.0
PERIOD_NS = round(1e9 / RATE)
STALL_S = 0.5  # longer than the old 0.1 s slip threshold, shorter than the 1 s one


def latest(peer: Peer) -> tuple[float, dict[str, str]]:
    """Arrival time (monotonic) and values of the last diagnostics received."""
    arrived, msg = peer.arrivals[-1]
    return arrived, diagnostics_values(msg)


def test_a_stalled_real_time_node_merges_the_late_ticks_and_keeps_simulated_time_with_wall_time(
        tmp_path):
    domain = next_domain_id()
    peer = Peer(domain)
    peer.arrivals = []
    peer.node.create_subscription(
        DiagnosticArray, "/diagnostics",
        lambda m: peer.arrivals.append((time.monotonic(), m)), 1000)
    node = NodeProcess(tmp_path, domain, dict(time_mode="realtime", publish_rate=RATE,
                                              sim_step=5e-4, merge_late_ticks=2,
                                              record_path="stall.mcap"))
    peer.watch = node
    try:
        peer.spin_until(lambda: len(peer.arrivals) >= 10, 60.0, "the node's diagnostics")
        w0, d0 = latest(peer)
        node.send(signal.SIGSTOP)
        try:
            end = time.monotonic() + STALL_S  # the stall itself, not a synchronisation
            while time.monotonic() < end:
                time.sleep(end - time.monotonic())
        finally:
            node.send(signal.SIGCONT)
        stalled = int(STALL_S * RATE)
        peer.spin_until(lambda: int(latest(peer)[1].get("merged_ticks", -1)) >= 0.8 * stalled,
                        30.0, f"about {stalled} merged ticks in the diagnostics")
        peer.spin_for(1.0)
        w1, d1 = latest(peer)
        assert node.stop() == 0
    finally:
        peer.close()
        if node.alive():
            node.kill()
    # Simulated time went on through the stall: the merged ticks' periods were stepped, and it
    # never ran ahead of the wall clock (the diagnostics' arrival times carry DDS delivery and
    # the 10 Hz window, a few ms). How closely it follows the wall clock depends on the
    # machine (`flexure-sim bench --node`).
    sim = float(d1["sim_time"]) - float(d0["sim_time"])
    merged = int(d1["merged_ticks"])
    assert merged >= 0.8 * stalled
    merged_since = merged - int(d0.get("merged_ticks", 0))
    assert merged_since / RATE <= sim <= (w1 - w0) + 0.1, (sim, w1 - w0, d1)
    assert int(d1["missed_ticks"]) >= merged
    assert int(d1["slips"]) == 0
    # The merged ticks are exactly the grid slots missing from the recording, up to the last
    # recorded diagnostics; every stamp is on the grid.
    log = read_log(tmp_path / "stall.mcap")
    assert log.complete
    last = log.messages_on("/diagnostics")[-1]
    assert diagnostics_values(last.message)["recording_dropped"] == "0"
    upto = last.log_time_ns
    stamps = [m.log_time_ns for m in log.messages_on("/output/displacement")
              if m.log_time_ns <= upto]
    assert all(t % PERIOD_NS == 0 for t in stamps)
    assert stamps == sorted(set(stamps))
    missing = upto // PERIOD_NS - len(stamps)
    assert missing == int(diagnostics_values(last.message)["merged_ticks"]) >= merged
