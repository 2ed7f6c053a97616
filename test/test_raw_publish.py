"""
The stepping thread's raw publish calls (`raw_publish.TickPublishers`), real rclpy and Fast DDS.

Held, they hand each message's bytes to rclpy's ``publish_raw``: a subscriber receives exactly
the bytes ``Publisher.publish`` would have sent; a publisher destroyed meanwhile stays usable
until the hold ends (its destruction deferred, as rclpy's per-call ``with`` defers it); outside
the hold, and for publishers that are no rclpy ones, the calls are the publishers' ``publish``.
"""
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64

from flexure_sim.node.publish.raw_publish import TickPublishers


class _Recorder:
    """A publisher that is no rclpy one: it keeps what it is given."""

    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def publish(self, data: bytes) -> None:
        self.sent.append(data)


def _qos() -> QoSProfile:
    return QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def test_held_calls_send_the_same_bytes_as_publish(context):
    node = rclpy.create_node("raw_publish_test", context=context)
    got: list[bytes] = []
    node.create_subscription(Float64, "value", got.append, _qos(), raw=True)
    pub = node.create_publisher(Float64, "value", _qos())
    other = _Recorder()
    calls = TickPublishers([other, pub], control_indices=[1])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + 30
        while pub.get_subscription_count() == 0:
            assert time.monotonic() < deadline, "publisher and subscription did not match"
            executor.spin_once(timeout_sec=0.05)
        payloads = [serialize_message(Float64(data=float(k) + 0.25)) for k in range(6)]
        assert calls.full[1] == pub.publish  # not held: rclpy's publish
        calls.full[1](payloads[0])
        with calls.hold():
            assert calls.held
            assert calls.full[1] != pub.publish and calls.control == [calls.full[1]]
            assert calls.full[0] == other.publish  # no rclpy handle: its own publish
            for payload in payloads[1:5]:
                calls.control[0](payload)
            calls.full[0](payloads[5])
        assert not calls.held and calls.full[1] == pub.publish
        calls.full[1](payloads[5])
        while len(got) < 6:
            assert time.monotonic() < deadline, f"received {len(got)} of 6"
            executor.spin_once(timeout_sec=0.05)
        assert got == payloads[:5] + [payloads[5]]
        assert [deserialize_message(b, Float64).data for b in got] == [
            k + 0.25 for k in range(6)]
        assert other.sent == [payloads[5]]
    finally:
        executor.shutdown()
        node.destroy_node()


def test_a_publisher_destroyed_while_held_lives_until_the_hold_ends(context):
    node = rclpy.create_node("raw_publish_destroy", context=context)
    pub = node.create_publisher(Float64, "value", _qos())
    calls = TickPublishers([pub], control_indices=[0])
    payload = serialize_message(Float64(data=1.5))
    try:
        with calls.hold():
            node.destroy_publisher(pub)  # deferred: the hold uses the handle
            calls.full[0](payload)  # still a valid publisher
        with pytest.raises(Exception, match="(?i)destr|invalid"):
            pub.publish(payload)  # destroyed once the hold ended
        with calls.hold():  # a destroyed handle cannot be held: publish() says why
            assert calls.full[0] == pub.publish
    finally:
        node.destroy_node()
