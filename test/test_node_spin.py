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

from flexure_sim.node.stage.main_loop import spin_until_stopped


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


class CountingExecutor(SingleThreadedExecutor):
    """Counts its waits; once `drop_next_wake` is set, loses the next wake-up (a lost wake)."""

    def __init__(self, *, context):
        super().__init__(context=context)
        self.waits = 0
        self.wakes = 0
        self.drop_next_wake = False

    def _spin_once_impl(self, *args, **kwargs):
        self.waits += 1
        return super()._spin_once_impl(*args, **kwargs)

    def wake(self):
        self.wakes += 1
        if self.drop_next_wake:
            self.drop_next_wake = False
            return
        super().wake()


def _counting(context):
    node = rclpy.create_node("spin_test", context=context)
    executor = CountingExecutor(context=context)
    executor.add_node(node)
    executor.spin_once(timeout_sec=0.05)  # whatever adding the node made ready
    executor.waits = 0
    return node, executor


def test_nothing_periodic_wakes_the_executor(context):
    """
    Over 3 s the loop waits once: it is woken by the end it waits for, not by a timeout.

    Every executor wake-up takes the GIL from the paced stepping thread for ~0.5 ms; the
    1 s timeout this loop had cost about one missed tick a second next to a controller
    (BENCHMARKS.md). With that timeout the executor below would wait at least three times.
    """
    node, executor = _counting(context)
    stopped = Future()
    threading.Timer(3.0, stopped.set_result, (True,)).start()
    spin_until_stopped(executor, stopped, context)
    assert stopped.done() and context.ok()
    assert executor.waits <= 2, f"the executor woke {executor.waits} times in 3 s"
    node.destroy_node()


def test_a_lost_shutdown_wake_up_is_made_good_by_the_watchdog(context):
    """The shutdown's own wake-up is lost; the watchdog wakes the executor, the loop ends."""
    node, executor = _counting(context)
    executor.drop_next_wake = True
    threading.Timer(0.2, context.try_shutdown).start()
    loop = threading.Thread(target=spin_until_stopped, args=(executor, Future(), context),
                            daemon=True)
    loop.start()
    loop.join(timeout=15.0)
    assert not loop.is_alive(), "the loop did not end after a shutdown whose wake-up was lost"
    assert not context.ok()
    assert not executor.drop_next_wake and executor.wakes >= 2
    node.destroy_node()
