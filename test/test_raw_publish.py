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
        calls.refresh()
        payloads = [serialize_message(Float64(data=float(k) + 0.25)) for k in range(6)]
        full = dict(calls.current(True))
        assert full[1] == pub.publish  # not held: rclpy's publish
        full[1](payloads[0])
        with calls.hold():
            assert calls.held
            full = dict(calls.current(True))
            assert full[1] != pub.publish and calls.current(False) == [(0, full[1])]
            assert full[0] == other.publish  # no rclpy handle: its own publish
            for payload in payloads[1:5]:
                calls.current(False)[0][1](payload)
            full[0](payloads[5])
        assert not calls.held and dict(calls.current(True))[1] == pub.publish
        dict(calls.current(True))[1](payloads[5])
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
    assert calls.current(True) == []  # nobody subscribes
    calls.set_subscribed(0, True)  # published as if a subscriber had matched
    payload = serialize_message(Float64(data=1.5))
    try:
        with calls.hold():
            node.destroy_publisher(pub)  # deferred: the hold uses the handle
            calls.current(True)[0][1](payload)  # still a valid publisher
        with pytest.raises(Exception, match="(?i)destr|invalid"):
            pub.publish(payload)  # destroyed once the hold ended
        with calls.hold():  # a destroyed handle cannot be held: publish() says why
            assert calls.current(True) == [(0, pub.publish)]
    finally:
        node.destroy_node()


def test_only_subscribed_topics_are_published_and_the_set_follows_subscribers(context):
    # Three real publishers; a real subscription comes and goes on the second. Control topics:
    # the second and third. A topic is published exactly while it has a subscriber.
    node = rclpy.create_node("raw_publish_subscribed", context=context)
    pubs = [node.create_publisher(Float64, f"topic{k}", _qos()) for k in range(3)]
    calls = TickPublishers(pubs, control_indices=[1, 2])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        assert calls.subscribed == [False, False, False] and calls.current(True) == []
        got: list[bytes] = []
        sub = node.create_subscription(Float64, "topic1", got.append, _qos(), raw=True)
        deadline = time.monotonic() + 30
        while pubs[1].get_subscription_count() == 0:
            assert time.monotonic() < deadline, "publisher and subscription did not match"
            executor.spin_once(timeout_sec=0.05)
        assert calls.current(True) == []  # nobody told it yet
        calls.refresh()
        assert calls.subscribed == [False, True, False] and calls.subscribed_count == 1
        payload = serialize_message(Float64(data=2.5))
        with calls.hold():
            assert [k for k, _ in calls.current(True)] == [1]
            assert [k for k, _ in calls.current(False)] == [0]  # first of the control topics
            calls.current(False)[0][1](payload)
        while not got:
            assert time.monotonic() < deadline, "the subscribed topic's message did not arrive"
            executor.spin_once(timeout_sec=0.05)
        assert got == [payload]
        node.destroy_subscription(sub)
        while pubs[1].get_subscription_count() != 0:
            assert time.monotonic() < deadline, "the subscription did not leave"
            executor.spin_once(timeout_sec=0.05)
        calls.set_subscribed(1, False)
        calls.set_subscribed(2, True)
        assert [k for k, _ in calls.current(True)] == [2]
        assert [k for k, _ in calls.current(False)] == [1]
    finally:
        executor.shutdown()
        node.destroy_node()
