"""
Shared test fixtures and markers. The repository root is importable: tests run the source tree.

Markers (a fast loop: ``scripts/run_tests.sh -m "not ros and not slow"``):
- ``ros``: set here on every test of a module that uses ROS 2 (rclpy, a DDS peer, the node or
  the ros2 tools as processes, colcon): found from the module's imports, so a new test module
  is marked without a list to keep;
- ``slow``: set by hand (``@pytest.mark.slow``) on tests that take seconds on a fast machine.
The whole suite, both included, is what CI runs.

scripts/run_tests.sh runs the suite on two pytest-xdist workers (``--dist loadgroup``): a module
with a module- or class-scoped fixture goes whole to one worker (its fixture made once), the
other tests one by one, slow ones first, then ROS ones, so that neither worker idles at the end
while the other runs a long test. node_harness gives each worker its own DDS domains.
"""
import os
import re
import signal
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
# Before anything imports NumPy: flexure_sim's BLAS settings (thread count, kernels) apply to
# the tests as to a user's process.
import flexure_sim  # noqa: E402,F401
#: The test process's DDS writers announce unacknowledged samples every 1 ms (the shipped
#: profile), so a peer can wait for the stage's acknowledgement of a command
#: (node_harness.Peer.publish_acked) in milliseconds instead of Fast DDS's 3 s heartbeat.
#: Read when the first participant is created; node subprocesses do not inherit it (node_env).
FAST_ACK_PROFILE = str(ROOT / "config" / "fastdds_fast_ack.xml")
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", FAST_ACK_PROFILE)

#: A test module that matches uses ROS 2 (see the module docstring).
_USES_ROS = re.compile(
    r"^\s*(from|import) (rclpy|node_harness|ros_workspace|multidrive_fixtures|std_srvs"
    r"|rosgraph_msgs|diagnostic_msgs|geometry_msgs|std_msgs|visualization_msgs)\b", re.M)


def pytest_configure(config):
    """
    Declare ``xdist_group`` where pytest-xdist is absent (``colcon test``); give Ctrl-C back.

    A shell without job control starts a background command (``.ci/run &``, a CI runner's
    step) with SIGINT ignored, and that disposition passes to every process it starts: a
    Python child then never raises KeyboardInterrupt, and the tests that press Ctrl-C on a
    child (``test_sweep``'s) saw the study run to its end (exit 0 instead of 130). The tests
    restore Python's own handler, so that the children they start get SIGINT as a terminal
    gives it (an installed handler is reset to the default across ``exec``).
    """
    config.addinivalue_line("markers", "xdist_group(name): the tests of one pytest-xdist worker")
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def _shares_a_fixture(item) -> bool:
    """Whether ``item`` uses a fixture made once for several tests of its module or class."""
    info = getattr(item, "_fixtureinfo", None)
    return info is not None and any(
        defs and defs[-1].scope in ("module", "class", "package")
        for defs in info.name2fixturedefs.values())


@pytest.hookimpl(tryfirst=True)  # before xdist's hook reads the groups
def pytest_collection_modifyitems(config, items):
    """
    Mark every test of a module that uses ROS 2 with ``ros``; group and order for xdist.

    A module with a shared fixture becomes one ``xdist_group`` (one worker runs it in order);
    the modules keep their order, and the other tests go out slow first, then ROS, then the
    rest (each in collection order). Every worker computes the same order (xdist checks it).
    """
    uses_ros: dict[str, bool] = {}
    modules: dict[str, list] = {}
    for item in items:
        path = str(item.fspath)
        if path not in uses_ros:
            uses_ros[path] = bool(_USES_ROS.search(Path(path).read_text(encoding="utf-8")))
        if uses_ros[path]:
            item.add_marker(pytest.mark.ros)
        modules.setdefault(path, []).append(item)
    grouped, single = [], []
    for path, tests in modules.items():
        if any(_shares_a_fixture(item) for item in tests):
            name = Path(path).name
            for item in tests:
                item.add_marker(pytest.mark.xdist_group(name))
            grouped += tests
        else:
            single += tests
    rank = {"slow": 0, "ros": 1}
    single.sort(key=lambda item: min([rank[m] for m in rank if item.get_closest_marker(m)],
                                     default=2))
    items[:] = grouped + single


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
def domain() -> int:
    """Return a fresh DDS domain id for one test (node_harness.next_domain_id)."""
    from node_harness import next_domain_id

    return next_domain_id()


@pytest.fixture
def peer(domain):
    """Return a real rclpy peer node (node_harness.Peer) on the test's `domain`."""
    from node_harness import Peer

    p = Peer(domain)
    yield p
    p.close()


@pytest.fixture
def peer_and_domain(peer, domain):
    """Return the test's `peer` and its `domain` as one pair."""
    return peer, domain
