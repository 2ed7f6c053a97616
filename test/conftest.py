"""Shared test fixtures. The repository root is importable so tests run against the source tree."""
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


@pytest.fixture
def context():
    """An rclpy context of its own, on this run's next DDS domain (ROS is imported only here:
    engine tests need none)."""
    import rclpy
    from rclpy.context import Context

    from node_harness import next_domain_id

    ctx = Context()
    rclpy.init(context=ctx, domain_id=next_domain_id())
    yield ctx
    rclpy.try_shutdown(context=ctx)
