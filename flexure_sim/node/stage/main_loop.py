"""
stage_node's main loop: the executor spins until a shutdown or the stepping thread's end.

The executor serves services, parameter changes and QoS events only (`shell`); everything
periodic runs in the stepping thread, so that the executor, whose every wake-up holds the GIL
for ~0.4 ms, stays asleep while the paced ticks run.
"""
from __future__ import annotations

import threading

from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future

#: Period of the main loop's watchdog (`spin_until_stopped`): the executor itself never wakes
#: on a timeout, since each wake-up holds the GIL for ~0.4 ms of the paced stepping thread.
WATCHDOG_PERIOD_S = 1.0


def spin_until_stopped(executor: Executor, stopped: Future, context: Context) -> None:
    """
    rclpy.spin, except that it also ends when `stopped` is done (the stepping thread ended).

    Only services, parameters and that end wake the executor. A timeout would wake it too: the
    1 s one this loop had cost the paced stepping thread ~0.5 ms of GIL on two or three ticks
    each second, about one missed tick a second next to a controller (BENCHMARKS.md). The
    safety net is a watchdog thread instead, should a shutdown or that end ever fail to wake
    the executor (a clean-clone run once had the node ignore SIGTERM for 30 s, not reproduced):
    once per WATCHDOG_PERIOD_S it looks, and wakes the executor only if it should have ended.

    A shutdown ends it wherever it lands. rclpy's signal handler shuts the context down
    concurrently with the executor, and when that lands while the executor builds its wait set,
    rclpy raises its implementation's RCLError ("the given context is not valid") rather than
    ExternalShutdownException: the same shutdown, not a failure. rclpy exports no public name
    for that error, so any exception raised once the context is shut down counts as the
    shutdown; while the context is ok it propagates.
    """
    ended = threading.Event()

    def watch() -> None:
        while not ended.wait(WATCHDOG_PERIOD_S):
            if not context.ok() or stopped.done():
                try:
                    executor.wake()
                except Exception:  # noqa: BLE001 - the executor is already gone
                    return

    threading.Thread(target=watch, name="spin-watchdog", daemon=True).start()
    try:
        while context.ok() and not stopped.done():
            executor.spin_until_future_complete(stopped)
    except ExternalShutdownException:
        pass
    except Exception:  # noqa: BLE001 - see the docstring: a shutdown's, unless the context is ok
        if context.ok():
            raise
    finally:
        ended.set()


def spin(node: Node) -> None:
    """`spin_until_stopped` of a stage node (``shell.StageNode``) in an executor of its own."""
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    spin_until_stopped(executor, node.stopped, node.context)
