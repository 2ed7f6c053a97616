"""
stage_node recording when the disk is slow or full (issue 16 items 3 and 12).

A real node subprocess, its real recorder process, real files read back.

The disk is slowed with the recorder's test hook (every write to the file sleeps) and filled
with a real 3 MiB tmpfs (needs root to mount it): room for a few complete 1 MiB chunks, full
after ~3 s of recording.
"""
from __future__ import annotations

import contextlib
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from std_srvs.srv import SetBool

from flexure_sim.node.record.process import MAX_BACKLOG_ENV, WRITE_DELAY_ENV
from flexure_sim.recording import read_log

from node_harness import ROOT, NodeProcess, Peer, diagnostics_values, next_domain_id, node_env

PERIOD_NS = 5_000_000  # publish_rate 200 Hz
TICK_TOPICS = (
    ["/bodies/poses"] + [f"/bodies/body{i}/pose" for i in range(1, 7)]
    + [f"/hinges/{h}/{kind}" for h in "abcdefg" for kind in ("wrench", "deflection")]
    + ["/hinges/a/compression", "/output/displacement", "/drive/input", "/drive/force"]
)
DROPPED = "flexure_sim.dropped_messages"


@pytest.fixture
def domain_peer() -> Iterator[tuple[int, Peer]]:
    """Return a fresh DDS domain and a test peer node in it."""
    domain = next_domain_id()
    peer = Peer(domain)
    try:
        yield domain, peer
    finally:
        peer.close()


def start(tmp_path: Path, domain_peer: tuple[int, Peer], time_mode: str, record_path: str,
          **env: str) -> NodeProcess:
    """
    Return the stage at 200 Hz recording to ``record_path`` (relative: in ``tmp_path/node``).

    It runs with extra environment variables (the recorder's test hooks), watched by the peer.
    """
    domain, peer = domain_peer
    cwd = tmp_path / "node"
    params = dict(time_mode=time_mode, sim_step=5e-4, publish_rate=200.0,
                  record_path=record_path)
    node = NodeProcess(cwd, domain, params, env=node_env(
        domain, PYTHONPATH=str(ROOT), ROS_LOG_DIR=str(cwd / "ros_log"), **env))
    peer.watch = node
    return node


def tick_stamps(log, topic: str) -> list[int]:
    return [m.log_time_ns for m in log.messages_on(topic)]


def test_fast_mode_waits_for_a_slow_recorder_and_loses_nothing(tmp_path, domain_peer):
    _, peer = domain_peer
    path = tmp_path / "node" / "fast.mcap"
    node = start(tmp_path, domain_peer, "fast", "fast.mcap", **{WRITE_DELAY_ENV: "0.2"})
    try:
        peer.spin_until(lambda: path.exists() and path.stat().st_size > 3_000_000, 90,
                        "3 MB recorded through a slow disk")
    finally:
        peer.watch = None
        assert node.stop() == 0, node.stderr
    log = read_log(path)
    assert log.complete
    assert log.bag_metadata["custom_data"][DROPPED] == "0"
    stamps = tick_stamps(log, "/bodies/poses")
    # Every tick from the first to the last, none missing: 2 s of simulated time at least.
    assert len(stamps) > 400
    assert stamps == list(range(stamps[0], stamps[-1] + 1, PERIOD_NS))
    for topic in TICK_TOPICS:
        assert tick_stamps(log, topic) == stamps, topic
    assert sum(log.counts[t] for t in TICK_TOPICS) == len(stamps) * len(TICK_TOPICS)
    assert "dropped" not in node.stderr


def test_real_time_drops_are_counted_in_diagnostics_and_file(tmp_path, domain_peer):
    _, peer = domain_peer
    path = tmp_path / "node" / "rt.mcap"
    # 1 s a write: the recorder falls behind at once (drops begin ~3 s in, as with 0.5 s or
    # 2 s), and the stop, which writes what the pipe still holds, takes ~11 s instead of 23.
    node = start(tmp_path, domain_peer, "realtime", "rt.mcap",
                 **{WRITE_DELAY_ENV: "1.0", MAX_BACKLOG_ENV: str(64 << 10)})
    peer.subscribe("/diagnostics", DiagnosticArray)

    def dropping() -> bool:
        last = peer.last("/diagnostics")
        return last is not None and int(diagnostics_values(last)["recording_dropped"]) > 0

    try:
        peer.wait_for_publishers(["/diagnostics"])
        peer.spin_until(dropping, 60, "diagnostics reporting dropped messages")
        status = peer.last("/diagnostics").status[0]
        reported = int(diagnostics_values(peer.last("/diagnostics"))["recording_dropped"])
    finally:
        peer.watch = None
        assert node.stop() == 0, node.stderr
    assert status.level == DiagnosticStatus.WARN
    assert f"{reported} messages not recorded" in status.message
    log = read_log(path)
    assert log.complete
    counted = int(log.bag_metadata["custom_data"][DROPPED])
    stamps = tick_stamps(log, "/bodies/poses")
    for topic in TICK_TOPICS:  # whole ticks are dropped: every tick topic has the same ticks
        assert tick_stamps(log, topic) == stamps, topic
    gaps = (stamps[-1] - stamps[0]) // PERIOD_NS + 1 - len(stamps)
    assert counted >= reported > 0
    assert counted >= gaps * len(TICK_TOPICS)
    assert f", {counted} dropped" in node.stderr


@pytest.fixture
def full_disk(tmp_path):
    """Return a real 3 MiB filesystem (tmpfs) that a recording fills in a few seconds."""
    mount = tmp_path / "small_fs"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(mount)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"needs root to mount a 3 MiB tmpfs: {done.stderr.strip()}")
    try:
        yield mount
    finally:
        with contextlib.suppress(subprocess.SubprocessError):
            subprocess.run(["umount", "-l", str(mount)], timeout=30)


def test_full_disk_is_one_error_line_no_traceback_and_the_node_goes_on(
        tmp_path, domain_peer, full_disk):
    _, peer = domain_peer
    path = full_disk / "run.mcap"
    node = start(tmp_path, domain_peer, "realtime", str(path))
    peer.subscribe("/diagnostics", DiagnosticArray)

    def failed() -> bool:
        last = peer.last("/diagnostics")
        return last is not None and last.status[0].level == DiagnosticStatus.ERROR

    try:
        peer.wait_for_publishers(["/diagnostics"])
        peer.spin_until(failed, 60, "diagnostics reporting the recording failure")
        status = peer.last("/diagnostics").status[0]
        seen = len(peer.received["/diagnostics"])
        peer.spin_until(lambda: len(peer.received["/diagnostics"]) >= seen + 3, 30,
                        "the node to go on publishing")
    finally:
        peer.watch = None
        assert node.stop() == 0, node.stderr
    assert "No space left on device" in status.message and str(path) in status.message
    assert diagnostics_values(peer.last("/diagnostics"))["recording"] == "false"
    err = node.stderr
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if "No space left on device" in line]
    assert lines and all("ERROR" in line for line in lines), err
    # What reached the disk before it filled up is readable: whole ticks, in order.
    log = read_log(path, recover=True)
    stamps = tick_stamps(log, "/bodies/poses")
    assert not log.complete and len(stamps) > 10
    assert stamps == list(range(stamps[0], stamps[-1] + 1, PERIOD_NS))


@pytest.mark.parametrize("layout", ["mcap file", "bag directory"])
def test_record_true_after_a_full_disk_starts_a_new_file_once_space_is_free(
        tmp_path, domain_peer, full_disk, layout):
    """The recorder stopped on ENOSPC; space freed, ``~/record true`` records to a new file."""
    domain, peer = domain_peer
    cwd = tmp_path / "node"
    params = dict(time_mode="realtime", sim_step=5e-4, publish_rate=200.0)
    if layout == "mcap file":
        params["record_path"] = str(full_disk / "run.mcap")
    else:
        params["record_dir"] = str(full_disk)
    node = NodeProcess(cwd, domain, params)
    peer.watch = node
    peer.subscribe("/diagnostics", DiagnosticArray)

    def failed() -> bool:
        last = peer.last("/diagnostics")
        return last is not None and last.status[0].level == DiagnosticStatus.ERROR

    try:
        peer.wait_for_publishers(["/diagnostics"])
        peer.spin_until(failed, 60, "diagnostics reporting the recording failure")
        for old in full_disk.iterdir():  # space is free again
            shutil.rmtree(old) if old.is_dir() else old.unlink()
        answer = peer.call(SetBool, "/stage_node/record", SetBool.Request(data=True))
        assert answer.success, answer.message
        new = Path(answer.message.removeprefix("recording to "))
        assert new.parent == full_disk, answer.message
        n = len(peer.received["/diagnostics"])
        peer.spin_until(lambda: any(
            diagnostics_values(m)["recording"] == "true"
            and int(diagnostics_values(m)["recorded_messages"]) > 0
            for m in peer.messages("/diagnostics")[n:]), 60, "the new recording")
        answer = peer.call(SetBool, "/stage_node/record", SetBool.Request(data=False))
        assert answer.success, answer.message
    finally:
        peer.watch = None
        assert node.stop() == 0, node.stderr
    log = read_log(new)
    assert log.complete
    stamps = tick_stamps(log, "/bodies/poses")
    assert stamps and stamps == list(range(stamps[0], stamps[-1] + 1, PERIOD_NS))
