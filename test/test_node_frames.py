"""
Frame ids of a real stage_node (subprocess) with a ``frame_prefix``.

Every frame id on every topic it publishes carries the prefix (issue 14, item 3).
"""
from __future__ import annotations

import signal

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, TransformStamped, WrenchStamped
from rclpy.node import NodeNameNonExistentError
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from flexure_sim.engine.mechanism.loader import load_mechanism

from node_harness import NodeProcess, Peer, next_domain_id

PREFIX = "stage1/"
#: Message classes by type name, for every type the node may publish.
CLASSES = {f"{c.__module__.split('.')[0]}/msg/{c.__name__}": c for c in (
    PoseArray, PoseStamped, TransformStamped, WrenchStamped, Float64, Clock, DiagnosticArray)}
try:
    from visualization_msgs.msg import MarkerArray
    CLASSES["visualization_msgs/msg/MarkerArray"] = MarkerArray
except ImportError:  # pragma: no cover - listed in requirements.txt
    pass


def frame_ids(msg) -> list[str]:
    """
    Every frame id a message carries.

    Its header's, a TransformStamped's child, and those of each element of a MarkerArray.
    """
    found = []
    if hasattr(msg, "header"):
        found.append(msg.header.frame_id)
    if hasattr(msg, "child_frame_id"):
        found.append(msg.child_frame_id)
    for marker in getattr(msg, "markers", []):
        found.append(marker.header.frame_id)
    return found


def expected_frames(prefix: str) -> set[str]:
    mech = load_mechanism("microstage")
    frames = {prefix + "stage"} | {prefix + b.name for b in mech.bodies}
    for h in mech.hinges:
        frames |= {f"{prefix}hinge_{h.name}", f"{prefix}hinge_{h.name}_a"}
    return frames


def test_every_published_frame_id_carries_the_frame_prefix(tmp_path):
    domain = next_domain_id()
    peer = Peer(domain)
    node = NodeProcess(tmp_path / "node", domain, {
        "time_mode": "lockstep", "publish_rate": 100.0, "record": False,
        "frame_prefix": PREFIX})
    peer.watch = node
    try:
        node.wait_for_output("topics per tick")
        # Every topic the node publishes, whatever its type, found through the graph.
        wanted = ["/bodies/poses", "/hinges/a/wrench", "/hinges/a/deflection", "/markers"]
        peer.wait_for_publishers(wanted)
        names: dict[str, str] = {}

        def graph_complete() -> bool:
            try:
                found = peer.node.get_publisher_names_and_types_by_node("stage_node", "/")
            except NodeNameNonExistentError:  # not yet discovered
                return False
            names.update((t, types[0]) for t, types in found)
            # 26 tick topics of the stage, /clock, diagnostics, markers (and TF where present)
            ours = [t for t, ty in names.items() if ty in CLASSES]
            return len(ours) >= 28 and set(wanted) <= set(names)

        peer.spin_until(graph_complete, 20, "the node's publishers in the graph")
        subscribed = {t: ty for t, ty in names.items() if ty in CLASSES and t != "/rosout"}
        for topic, type_name in subscribed.items():
            peer.subscribe(topic, CLASSES[type_name])
        stamped = [t for t, ty in subscribed.items()
                   if ty != "std_msgs/msg/Float64" and ty != "rosgraph_msgs/msg/Clock"]
        # Reliable, volatile: a subscription hears ticks after it matched; step until every
        # stamped topic has been heard (markers come at the display rate, every few ticks).
        for _ in range(200):
            assert peer.call(Trigger, "/stage_node/step").success
            peer.executor.spin_once(timeout_sec=0.05)
            if all(peer.received[t] for t in stamped):
                break
        peer.spin_until(lambda: all(peer.received[t] for t in stamped), 20, "a message per topic")
    finally:
        rc = node.stop(signal.SIGINT)
        peer.close()
    assert rc == 0, node.stderr
    seen = set()
    for topic in stamped:
        for msg in peer.messages(topic):
            for frame in frame_ids(msg):
                if frame:  # diagnostics carry no frame
                    assert frame.startswith(PREFIX), f"{topic}: frame id {frame!r}"
                    seen.add(frame)
    # The stamped topics: poses, 7 wrenches and deflections, markers (and TF where present).
    assert {"/markers", "/bodies/poses", "/bodies/body3/pose",
            "/hinges/g/deflection"} <= set(stamped)
    assert seen <= expected_frames(PREFIX)
    assert {PREFIX + "stage", PREFIX + "hinge_a", PREFIX + "hinge_a_a"} <= seen
