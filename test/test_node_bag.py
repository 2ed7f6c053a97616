"""
stage_node (a real subprocess) recording rosbag2 bag directories (issue 14, item 5).

After ~/reset, ~/record false, SIGINT, SIGTERM and kill -9 of the node, each directory has a
metadata.yaml whose counts equal its MCAP files', and rosbags opens it as a rosbag2 bag.
"""
from __future__ import annotations

import signal
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
from std_srvs.srv import SetBool, Trigger

from node_harness import NodeProcess, Peer, next_domain_id


def check_bag(directory: Path) -> dict:
    """
    Assert that metadata.yaml counts what the bag's MCAP files hold; return the metadata.

    The files are read with mcap, an independent reader, and rosbags must open the directory.
    """
    meta = yaml.safe_load((directory / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert sorted(p.name for p in directory.glob("*.mcap")) == sorted(meta["relative_file_paths"])
    per_topic: dict[str, int] = {}
    for entry in meta["files"]:
        with open(directory / entry["path"], "rb") as f:
            reader = make_reader(f)
            stats = reader.get_summary().statistics  # a complete file: summary and statistics
            held = [ch.topic for _, ch, _ in reader.iter_messages()]
        assert entry["message_count"] == stats.message_count == len(held), entry["path"]
        for topic in held:
            per_topic[topic] = per_topic.get(topic, 0) + 1
    counted = {t["topic_metadata"]["name"]: t["message_count"]
               for t in meta["topics_with_message_count"]}
    assert {t: n for t, n in counted.items() if n} == per_topic
    assert meta["message_count"] == sum(per_topic.values())
    with Reader(directory) as bag:
        assert bag.message_count == meta["message_count"]
        assert {c.topic: c.msgcount for c in bag.connections if c.msgcount} == per_topic
    return meta


def test_reset_record_stop_and_sigint_each_leave_a_counted_bag(tmp_path):
    domain = next_domain_id()
    peer = Peer(domain)
    node = NodeProcess(tmp_path / "node", domain, {
        "time_mode": "lockstep", "publish_rate": 100.0, "record_path": "run",
        "record_max_duration": 0.05})  # a new file every 5 ticks (50 ms of simulated time)
    peer.watch = node

    def steps(n: int) -> None:
        for _ in range(n):
            assert peer.call(Trigger, "/stage_node/step").success

    try:
        node.wait_for_output("topics per tick")
        steps(12)
        answer = peer.call(Trigger, "/stage_node/reset")  # closes run, opens run_1
        assert answer.success and "closed run" in answer.message, answer.message
        steps(3)
        answer = peer.call(SetBool, "/stage_node/record", SetBool.Request(data=False))
        assert answer.success and "closed run_1" in answer.message, answer.message
        answer = peer.call(SetBool, "/stage_node/record", SetBool.Request(data=True))
        assert answer.success and "run_2" in answer.message, answer.message
        steps(7)
    finally:
        rc = node.stop(signal.SIGINT)
        peer.close()
    assert rc == 0, node.stderr
    bags = {name: check_bag(node.cwd / name) for name in ("run", "run_1", "run_2")}
    # Ticks per file: 12 = 5 + 5 + 2 (split by simulated time), 3, 7 = 5 + 2.
    poses = {name: [t["message_count"] for t in m["topics_with_message_count"]
                    if t["topic_metadata"]["name"] == "/bodies/poses"][0]
             for name, m in bags.items()}
    assert poses == {"run": 12, "run_1": 3, "run_2": 7}
    assert [len(m["files"]) for m in bags.values()] == [3, 1, 2]


@pytest.mark.parametrize("how", ["SIGTERM", "kill -9"])
def test_the_bag_is_finished_when_the_node_is_stopped_or_killed(tmp_path, how):
    domain = next_domain_id()
    node = NodeProcess(tmp_path / "node", domain, {
        "time_mode": "fast", "publish_rate": 1000.0, "record_path": "fast",
        "record_max_duration": 0.5})
    bag = node.cwd / "fast"
    try:
        # Running: a first file has been finished (metadata.yaml written) and the next begun.
        node.wait_for_output("recording to fast")
        peer = Peer(domain)
        peer.watch = node
        try:
            peer.spin_until(lambda: (bag / "fast_1.mcap").exists(), 60, "a second file")
        finally:
            peer.close()
        recorder = node.children()
        if how == "SIGTERM":
            assert node.stop(signal.SIGTERM) == 0, node.stderr
        else:
            node.kill()
            # The recorder process reads the end of the pipe and finishes the bag on its own.
            (pid,) = recorder
            peer = Peer(domain)
            try:
                peer.spin_until(lambda: not Path(f"/proc/{pid}").exists(), 60,
                                "the recorder to finish")
            finally:
                peer.close()
    finally:
        node.kill()
    meta = check_bag(bag)
    assert len(meta["files"]) >= 2 and meta["message_count"] > 1000
