"""
A controller's measurements taken and answered in its main thread, without rclpy's executor.

Why: rclpy's executors rebuild their wait set in Python on every wake-up, and a controller
that answers every measurement wakes at the stage's tick rate. Measured on a 2-core VM (a
process answering each Float64 of a 2 kHz stream with one Float64; CPU time of the answering
process per message, 13,000 messages, one run each): ``SingleThreadedExecutor`` 293 us (its
thread alone 281 us, 275 us without the node's parameter services), this loop (`serve`)
102 us, ``rclpy.experimental.EventsExecutor`` 94 us. At 2 kHz the executor's cost alone is
more than half a core, and a reply that waits for it misses the stage's next tick (the ping-pong
floor, ``bench/pingpong.py``, on that VM: 93.4-98.2 % answered at the next tick with
``rclpy.spin``, 99.6-99.7 % with this loop). The EventsExecutor deadlocked at shutdown in this
rclpy (7.1.6): its spinning thread keeps a lock that ``Context.try_shutdown`` waits for.

How: the subscriptions are created in a `PolledGroup` (the executor never waits on them);
`serve` waits on them with a wait set of its own, reused from one wake-up to the next, and
runs their callbacks in the calling thread. A ``SingleThreadedExecutor`` in a second thread
serves the rest of the node (services, parameters), which wakes it only when asked. The wait
set is rclpy's own (``_rclpy.WaitSet``, as ``rclpy.wait_for_message`` uses it): rclpy
(Jazzy) has no public wait set. test_answer_loop.py fails if it changes.
SIGINT and SIGTERM end `serve` with KeyboardInterrupt, as they end ``rclpy.spin``; a
shutdown of the context ends it with ExternalShutdownException, wherever it lands (rclpy
raises its implementation's RCLError when it lands while a wait set or guard condition is
being made: any exception once the context is shut down counts as that shutdown, as in
``stage.main_loop``).
"""
from __future__ import annotations

import threading
from typing import Any, Callable, Sequence

from rclpy.exceptions import InvalidHandle
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerGuardCondition
from rclpy.subscription import Subscription

#: How long the executor thread may take to end once the context is shut down, s.
JOIN_TIMEOUT_S = 10.0


def _spin_rest(executor: SingleThreadedExecutor) -> None:
    """Spin the executor of the node's other entities until shutdown (executor thread)."""
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass


class AnswerLoop:
    """`serve` a node: its polled subscriptions in the calling thread, the rest in a thread."""

    def __init__(self, node: Node, polled: Sequence[tuple[Subscription, Callable[[Any], None]]]):
        self.node = node
        self.polled = list(polled)
        self._stop = GuardCondition(None, None, context=node.context)
        node.context.on_shutdown(self.stop)
        #: Set once `serve` waits for the first message.
        self.serving = threading.Event()

    def stop(self) -> None:
        """End `serve` (from any thread; also called when the context shuts down)."""
        try:
            self._stop.trigger()
        except InvalidHandle:  # already ended
            pass

    def serve(self) -> None:
        """Answer the polled subscriptions until `stop` or shutdown (module docstring)."""
        context = self.node.context
        if not context.ok():
            raise ExternalShutdownException()
        try:
            self._serve(context)
        except (KeyboardInterrupt, ExternalShutdownException):
            raise
        except Exception as exc:
            if context.ok():
                raise
            raise ExternalShutdownException() from exc
        if not context.ok():
            raise ExternalShutdownException()

    def _serve(self, context: Any) -> None:
        """Start the executor thread, run `_loop`, end the thread."""
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(self.node)
        rest = threading.Thread(target=_spin_rest, args=(executor,), name="answer-loop-rest",
                                daemon=True)
        rest.start()
        signals = None
        try:
            signals = SignalHandlerGuardCondition(context)
            self._loop(context, signals)
        finally:
            if signals is not None:
                signals.destroy()
            executor.shutdown(timeout_sec=0)
            rest.join(JOIN_TIMEOUT_S)

    def _loop(self, context: Any, signals: SignalHandlerGuardCondition) -> None:
        """Wait on the polled subscriptions and the two guard conditions; run what is ready."""
        handles = [sub.handle for sub, _ in self.polled]
        calls = {sub.handle.pointer: (sub, callback) for sub, callback in self.polled}
        guards = (signals.handle, self._stop.handle)
        with context.handle, signals.handle, self._stop.handle:
            for handle in handles:
                handle.__enter__()
            try:
                wait_set = _rclpy.WaitSet(len(handles), len(guards), 0, 0, 0, 0, context.handle)
                self.serving.set()
                while context.ok():
                    wait_set.clear_entities()
                    for handle in handles:
                        wait_set.add_subscription(handle)
                    for guard in guards:
                        wait_set.add_guard_condition(guard)
                    wait_set.wait(-1)
                    ready_guards = wait_set.get_ready_entities("guard_condition")
                    if signals.handle.pointer in ready_guards:
                        raise KeyboardInterrupt
                    if self._stop.handle.pointer in ready_guards:
                        return
                    for pointer in wait_set.get_ready_entities("subscription"):
                        sub, callback = calls[pointer]
                        taken = sub.handle.take_message(sub.msg_type, sub.raw)
                        if taken is not None:
                            callback(taken[0])
            finally:
                for handle in reversed(handles):
                    handle.__exit__(None, None, None)
