"""
stage_node publishes a tick topic while it has a subscriber, and records every topic always.

A real node process and a real rclpy peer: the diagnostics' ``subscribed_topics`` follows the
peer's subscriptions as they come and go (the publishers' matched events), a subscriber that
joins a running node receives its topic at once, and the recording holds every tick topic for
every tick whoever listened (`raw_publish`).
"""
from __future__ import annotations

import signal

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from mcap.reader import make_reader
from std_msgs.msg import Float64

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.node.publish.interface import StageInterface

from node_harness import NodeProcess, diagnostics_values

OUTPUT = "/output/displacement"


def test_topics_are_published_while_subscribed_and_recorded_always(tmp_path, peer_and_domain):
    peer, domain = peer_and_domain
    interface = StageInterface(load_mechanism("microstage"), "realtime")
    tick_topics = ["/" + spec.name.lstrip("/") for spec in interface.tick_topics]
    pose = next(t for t, spec in zip(tick_topics, interface.tick_topics)
                if spec.msg_type is PoseStamped)
    assert OUTPUT in tick_topics and len(tick_topics) > 2
    node = NodeProcess(tmp_path / "node", domain, dict(time_mode="realtime", publish_rate=200.0,
                                                       sim_step=1e-4, record=True,
                                                       record_path="subscribed.mcap"))
    peer.watch = node

    def subscribed() -> int:
        msg = peer.last("/diagnostics")
        return -1 if msg is None else int(diagnostics_values(msg)["subscribed_topics"])

    try:
        peer.subscribe("/diagnostics", DiagnosticArray)  # not a tick topic
        peer.wait_for_publishers(["/diagnostics"])
        peer.spin_until(lambda: subscribed() == 0, 20, "diagnostics with no topic subscribed")
        peer.subscribe(OUTPUT, Float64)
        peer.spin_until(lambda: subscribed() == 1 and len(peer.messages(OUTPUT)) >= 5, 20,
                        f"{OUTPUT} subscribed and received")
        peer.subscribe(pose, PoseStamped)
        peer.spin_until(lambda: subscribed() == 2 and len(peer.messages(pose)) >= 5, 20,
                        f"{pose} subscribed too")
        for sub in [s for s in peer.node.subscriptions if s.topic_name in (OUTPUT, pose)]:
            peer.node.destroy_subscription(sub)
        peer.spin_until(lambda: subscribed() == 0, 20, "both subscriptions gone")
        ticks = int(diagnostics_values(peer.last("/diagnostics"))["ticks"])
    finally:
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr
    counts = dict.fromkeys(tick_topics, 0)
    for path in node.recordings():
        with open(path, "rb") as f:
            for _, channel, _ in make_reader(f).iter_messages():
                if channel.topic in counts:
                    counts[channel.topic] += 1
    assert len(set(counts.values())) == 1, counts  # every tick topic, every tick
    assert counts[OUTPUT] >= ticks > 0
