"""
stage_node's main loop (in-process rclpy, real Fast DDS on loopback).

A shutdown ends it cleanly wherever it lands, also inside the executor's wait-set build, where
rclpy's SIGTERM thread can land it (CI saw the node exit 1 with RCLError "the given context is not
valid").
"""
import threading

import pytest
import rclpy
from rclpy.callback_groups import CallbackGroup
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.task import Future
from std_msgs.msg import Float64

from flexure_sim.node.shell import spin_until_stopped


class ShutdownWhileCollecting(CallbackGroup):
    """
    Shuts its context down when the executor asks about its entity.

    That is while the executor collects the entities of its next wait set, before it builds it.
    """

    def __init__(self, context: Context):
        super().__init__()
        self.context = context
        self.asked = 0

    def can_execute(self, entity) -> bool:
        self.asked += 1
        self.context.try_shutdown()
        return False

    def beginning_execution(self, entity) -> bool:
        return False

    def ending_execution(self, entity) -> None:
        pass


def _node_and_executor(context, group):
    node = rclpy.create_node("spin_test", context=context)
    node.create_subscription(Float64, "cmd", lambda _: None, 10, callback_group=group)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    return node, executor


def test_the_race_is_real_a_bare_spin_raises(context):
    """Control: the same shutdown point makes rclpy's own spin raise RCLError."""
    group = ShutdownWhileCollecting(context)
    node, executor = _node_and_executor(context, group)
    with pytest.raises(_rclpy.RCLError, match="context is not valid"):
        executor.spin_until_future_complete(Future(), timeout_sec=1.0)
    assert group.asked >= 1
    node.destroy_node()


def test_a_shutdown_inside_the_wait_set_build_ends_the_loop_cleanly(context):
    group = ShutdownWhileCollecting(context)
    node, executor = _node_and_executor(context, group)
    spin_until_stopped(executor, Future(), context)  # returns, raises nothing
    assert group.asked >= 1 and not context.ok()
    node.destroy_node()


def test_the_loop_ends_when_stopped_and_on_a_shutdown_from_another_thread(context):
    node = rclpy.create_node("spin_test", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stopped = Future()
    threading.Timer(0.2, stopped.set_result, (True,)).start()
    spin_until_stopped(executor, stopped, context)
    assert stopped.done() and context.ok()
    threading.Timer(0.2, context.try_shutdown).start()
    spin_until_stopped(executor, Future(), context)
    assert not context.ok()
    node.destroy_node()
