"""Shared test fixtures. The repository root is importable so tests run against the source tree."""
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
#: The test process's DDS writers announce unacknowledged samples every 1 ms (the shipped
#: profile), so a peer can wait for the stage's acknowledgement of a command
#: (node_harness.Peer.publish_acked) in milliseconds instead of Fast DDS's 3 s heartbeat.
#: Read when the first participant is created; node subprocesses do not inherit it (node_env).
FAST_ACK_PROFILE = str(ROOT / "config" / "fastdds_fast_ack.xml")
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", FAST_ACK_PROFILE)


@pytest.fixture
def context():
    """
    Return an rclpy context of its own.

    It is on this run's next DDS domain (ROS is imported only here: engine tests need none).
    """
    import rclpy
    from rclpy.context import Context

    from node_harness import next_domain_id

    ctx = Context()
    rclpy.init(context=ctx, domain_id=next_domain_id())
    yield ctx
    rclpy.try_shutdown(context=ctx)


@pytest.fixture
def peer_and_domain():
    """Return a fresh DDS domain and a real rclpy peer node on it (node_harness.Peer)."""
    from node_harness import Peer, next_domain_id

    domain = next_domain_id()
    peer = Peer(domain)
    yield peer, domain
    peer.close()
