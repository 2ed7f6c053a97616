"""
Commands a publisher sent that the node never took are counted, not lost silently.

`SequenceGaps` on hand-made sequences whose losses are known by construction; then a real
node (lockstep, a command reader one command deep) under a real publisher that sends more
commands between two ticks than the reader holds: the commands recorded plus the commands
counted as lost equal the commands sent, exactly, and the diagnostics and the log say so.
"""
from __future__ import annotations

import signal

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.duration import Duration
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from flexure_sim.node.inputs.command_loss import SequenceGaps
from flexure_sim.recording import read_log
from node_harness import NodeProcess, Peer, diagnostics_values, next_domain_id


def gaps(numbers, publishers=1) -> int:
    counter = SequenceGaps(lambda: publishers)
    return counter.observe(numbers)


def test_gaps_of_one_publisher_are_the_numbers_skipped():
    assert gaps([1, 2, 3, 4]) == 0
    assert gaps([5, 9, 10, 20]) == 3 + 9  # joined at 5: what came before is not counted
    counter = SequenceGaps(lambda: 1)
    assert counter.observe([1, 2]) == 0 and counter.observe([5]) == 2
    assert counter.observe([6, 7]) == 0 and counter.lost == 2


def test_commands_numbered_before_the_first_taken_are_counted_apart():
    counter = SequenceGaps(lambda: 1)
    assert counter.observe([5, 6, 9]) == 2       # joined at 5: 1..4 came before the node heard it
    assert counter.unheard == 4
    assert counter.observe([1, 2]) == 0          # restarted: numbered anew, nothing unheard
    assert counter.unheard == 4 and counter.lost == 2
    two = SequenceGaps(lambda: 2)
    assert two.observe([1, 2, 40, 3, 41]) == 0   # B joined at 40: 39 unheard, none lost
    assert two.unheard == 39


def test_a_restarted_publisher_and_numbers_going_back_count_nothing():
    assert gaps([1, 2, 3, 50, 1, 2, 3]) == 46   # a publisher restarted after 50: numbered anew
    assert gaps([10, 9, 8, 7]) == 0             # never negative
    assert gaps([3, None, 4, None, 6]) == 1     # None: no number from the middleware


def test_interleaved_publishers_are_told_apart_by_continuity():
    # Publisher A 1..10 (4 and 7 lost), B 1..6 (5 lost), interleaved; two publishers matched.
    a = [1, 2, 3, 5, 6, 8, 9, 10]
    b = [1, 2, 3, 4, 6]
    merged = [a[0], b[0], a[1], b[1], a[2], b[2], a[3], b[3], a[4], b[4], a[5], a[6], a[7]]
    assert gaps(merged, publishers=2) == 3
    # B joined before the node's reader saw it, at 40: its first number is no loss of A's.
    assert gaps([1, 2, 40, 3, 41, 4], publishers=2) == 0


def _diag(peer: Peer) -> dict[str, str]:
    return diagnostics_values(peer.last("/diagnostics"))


def test_a_flood_beyond_the_reader_is_counted_exactly(tmp_path):
    """
    Sent == recorded + lost, with a publisher restart in between (a new writer, numbered anew).

    Deterministic by construction: the node ticks only on ~/step (lockstep); each burst is
    acknowledged by the node's reader (one command deep) before the next step, so the reader
    holds only the burst's last command and the step takes that one.
    """
    domain = next_domain_id()
    node = NodeProcess(tmp_path / "node", domain, {
        "time_mode": "lockstep", "publish_rate": 10.0, "sim_step": 1e-4, "command_depth": 1,
        "record": True, "record_path": "loss.mcap"})
    peer = Peer(domain)
    peer.watch = node
    ticks = 0

    def step() -> dict[str, str]:
        nonlocal ticks
        answer = peer.call(Trigger, "/stage_node/step")
        assert answer.success, answer.message
        ticks += 1
        peer.spin_until(lambda: peer.last("/diagnostics") is not None
                        and int(_diag(peer)["ticks"]) >= ticks, 30, f"diagnostics of tick {ticks}")
        return _diag(peer)

    def burst(publisher, values) -> None:
        for v in values:
            publisher.publish(Float64(data=v))
        assert publisher.wait_for_all_acked(Duration(seconds=30))

    sent = 0
    bursts = [(1, 40), (1, 25)]  # per publisher: a first command alone, then a burst
    try:
        node.wait_for_output("topics per tick", 120)
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.wait_for_publishers(["/diagnostics"])
        for p, (first, flood) in enumerate(bursts):
            pub = peer.publisher("/drive/displacement", Float64)
            peer.wait_for_subscribers(pub)
            for n in (first, flood):
                burst(pub, [1e-8 * (p + 1) * (k + 1) for k in range(n)])
                sent += n
                d = step()
                status = peer.last("/diagnostics").status[0]
                if n == flood:  # the tick that took the burst's last: WARN, with the count
                    assert status.level == DiagnosticStatus.WARN, status.message
                    assert f"{n - 1} commands lost" in status.message, status.message
            peer.node.destroy_publisher(pub)  # the next publisher is a new writer: 1, 2, ...
        d = step()
    finally:
        peer.watch = None
        peer.close()
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    recorded = read_log(node.cwd / "loss.mcap").messages_on("/drive/displacement")
    lost = int(d["commands_lost"])
    assert len(recorded) + lost == sent
    assert lost == sum(flood - 1 for _, flood in bursts)  # each burst: only its last was taken
    assert int(d["commands_received"]) == len(recorded) == 2 * len(bursts)
    assert [m.message.data for m in recorded] == [
        1e-8 * (p + 1) * n for p, (first, flood) in enumerate(bursts) for n in (first, flood)]
    assert "commands lost: a publisher sent 39 commands the node never took" in node.stderr


def test_commands_sent_before_the_node_listened_are_counted_as_unheard(tmp_path):
    """
    Sent == recorded + lost + unheard: a publisher that sent before the node existed.

    Deterministic by construction: the publisher's first commands are published before the
    node's process starts, so no reader can have received them (a volatile writer keeps
    nothing for late readers); the next one is acknowledged by the node's reader before the
    step that takes it.
    """
    domain = next_domain_id()
    peer = Peer(domain)
    early = 7
    node = None
    try:
        pub = peer.publisher("/drive/displacement", Float64)
        for k in range(early):
            pub.publish(Float64(data=1e-8 * (k + 1)))
        node = NodeProcess(tmp_path / "node", domain, {
            "time_mode": "lockstep", "publish_rate": 10.0, "sim_step": 1e-4,
            "record": True, "record_path": "early.mcap"})
        peer.watch = node
        node.wait_for_output("topics per tick", 120)
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.wait_for_publishers(["/diagnostics"])
        peer.wait_for_subscribers(pub)
        pub.publish(Float64(data=1e-6))
        assert pub.wait_for_all_acked(Duration(seconds=30))
        answer = peer.call(Trigger, "/stage_node/step")
        assert answer.success, answer.message
        peer.spin_until(lambda: peer.last("/diagnostics") is not None
                        and int(_diag(peer)["ticks"]) >= 1, 30, "diagnostics of tick 1")
        d = _diag(peer)
    finally:
        peer.watch = None
        peer.close()
        rc = node.stop(signal.SIGINT) if node is not None else 0
    assert rc == 0, node.stderr
    recorded = read_log(node.cwd / "early.mcap").messages_on("/drive/displacement")
    assert [m.message.data for m in recorded] == [1e-6]
    assert int(d["commands_lost"]) == 0
    assert int(d["commands_unheard"]) == early
    assert len(recorded) + int(d["commands_lost"]) + int(d["commands_unheard"]) == early + 1


def test_the_recordings_last_status_holds_the_commands_taken_up_to_the_stop(tmp_path):
    """
    A stop records one more status: its counters are the whole run's (what ``analyse`` reads).

    At 1 kHz the node reports every 100 ticks; this run stops after 3 ticks, each taking a
    command acknowledged by the node's reader before its step, so only the status written at
    the stop can count them.
    """
    domain = next_domain_id()
    node = NodeProcess(tmp_path / "node", domain, {
        "time_mode": "lockstep", "publish_rate": 1000.0, "sim_step": 1e-4,
        "record": True, "record_path": "stop.mcap"})
    peer = Peer(domain)
    peer.watch = node
    values = [2e-7, 4e-7, 6e-7]
    try:
        node.wait_for_output("topics per tick", 120)
        pub = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_subscribers(pub)
        for v in values:
            pub.publish(Float64(data=v))
            assert pub.wait_for_all_acked(Duration(seconds=30))
            answer = peer.call(Trigger, "/stage_node/step")
            assert answer.success, answer.message
    finally:
        peer.watch = None
        peer.close()
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    log = read_log(node.cwd / "stop.mcap")
    assert [m.message.data for m in log.messages_on("/drive/displacement")] == values
    statuses = log.messages_on("/diagnostics")
    assert len(statuses) == 1  # no periodic one within 3 ticks: the stop's
    d = diagnostics_values(statuses[-1].message)
    assert int(d["ticks"]) == 3 and statuses[-1].log_time_ns == 3_000_000
    assert int(d["commands_received"]) == int(d["commands_accepted"]) == len(values)
