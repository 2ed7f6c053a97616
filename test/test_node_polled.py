"""
Polled subscriptions (in-process rclpy, real Fast DDS on loopback).

The executor never runs or waits on them; the stepping thread's `take_raw` gets every message, in
order.
"""
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64

from flexure_sim.node.publish.qos_profiles import command_qos
from flexure_sim.node.stage.polled import PolledGroup, take_raw


def test_polled_subscription_never_wakes_the_executor_and_loses_nothing(context):
    node = rclpy.create_node("polled_test", context=context)
    calls = []
    sub = node.create_subscription(Float64, "cmd", calls.append, command_qos(), raw=True,
                                   callback_group=PolledGroup())
    pub = node.create_publisher(Float64, "cmd", command_qos())
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        deadline = time.monotonic() + 10
        while pub.get_subscription_count() == 0:
            assert time.monotonic() < deadline, "publisher and subscription did not match"
            time.sleep(0.01)
        for k in range(250):
            pub.publish(Float64(data=float(k)))
        time.sleep(0.2)
        # The executor has nothing to wait on but the messages: it times out and runs nothing.
        t0 = time.monotonic()
        executor.spin_once(timeout_sec=0.3)
        assert time.monotonic() - t0 >= 0.25
        assert calls == []
        first = take_raw(sub, 100)
        rest = take_raw(sub, 1000)
        assert len(first) == 100 and len(rest) == 150
        values = [deserialize_message(b, Float64).data for b in first + rest]
        assert values == [float(k) for k in range(250)]
        assert take_raw(sub, 10) == []
        # The subscription is the node's own: introspection lists it under the node.
        topics = dict(node.get_subscriber_names_and_types_by_node("polled_test", "/"))
        assert topics["/cmd"] == ["std_msgs/msg/Float64"]
    finally:
        executor.shutdown()
        node.destroy_node()
    assert take_raw(sub, 10) == []  # destroyed: nothing, no exception
