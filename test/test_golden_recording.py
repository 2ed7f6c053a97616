"""
A golden lockstep recording: refactors and speed-ups must not change a published byte.

The stage node (a real subprocess, lockstep mode, 2 kHz ticks of 5 engine steps) is driven by
the demo driver through a short profile and records it; every channel's messages -- log and
publish times and the CDR payload -- are hashed and compared with ``data/golden_lockstep.json``,
written from the code before the work it guards. The diagnostics channel carries wall-clock
timings and is compared by count only.

Regenerate (only when a change of the published bytes is intended, and say why in the
commit): ``FLEXURE_GOLDEN_WRITE=1 scripts/run_tests.sh test/test_golden_recording.py``.
"""
from __future__ import annotations

import hashlib
import json
import os
import signal
import struct
import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

from conftest import ROOT
from node_harness import NodeProcess, next_domain_id, node_env

GOLDEN = Path(__file__).parent / "data" / "golden_lockstep.json"
#: Channels whose payload holds wall-clock figures: their message count is compared only.
COUNT_ONLY = ("/diagnostics", "/rosout")


def recording_digest(directory: Path) -> dict[str, dict[str, object]]:
    """Per topic: message count and SHA-256 of (log time, publish time, payload) in file order."""
    out: dict[str, dict[str, object]] = {}
    digests: dict[str, "hashlib._Hash"] = {}
    for path in sorted(directory.glob("*.mcap")):
        with open(path, "rb") as f:
            for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
                entry = out.setdefault(channel.topic, {"count": 0})
                entry["count"] = int(entry["count"]) + 1
                if channel.topic in COUNT_ONLY:
                    continue
                h = digests.setdefault(channel.topic, hashlib.sha256())
                h.update(struct.pack("<QQI", message.log_time, message.publish_time,
                                     len(message.data)))
                h.update(message.data)
    for topic, h in digests.items():
        out[topic]["sha256"] = h.hexdigest()
    return out


def test_a_short_lockstep_run_records_the_golden_bytes(tmp_path):
    domain = next_domain_id()
    node = NodeProcess(tmp_path / "node", domain, {
        "mechanism": "microstage", "time_mode": "lockstep", "publish_rate": 2000.0,
        "record": False, "record_path": "golden"})
    try:
        node.wait_for_output("topics per tick")
        env = node_env(domain, PYTHONPATH=str(ROOT), ROS_LOG_DIR=str(tmp_path / "ros_log"))
        drive = subprocess.run(
            [sys.executable, "-m", "flexure_sim.node.apps.demo_drive", "--record",
             "--rest", "0.005", "--dwell", "0.01", "--json"],
            env=env, capture_output=True, text=True, timeout=300)
        assert drive.returncode == 0, drive.stderr
    finally:
        rc = node.stop(signal.SIGINT)
    assert rc == 0, node.stderr()
    got = recording_digest(node.cwd / "golden")
    assert got, "nothing was recorded"
    if os.environ.get("FLEXURE_GOLDEN_WRITE") == "1":
        GOLDEN.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
    want = json.loads(GOLDEN.read_text())
    differ = sorted(t for t in set(want) | set(got) if want.get(t) != got.get(t))
    assert not differ, f"channels whose recorded bytes changed: {differ}"
