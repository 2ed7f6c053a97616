"""
Hand-over of work from the executor (services, parameter changes) to the stepping thread.

The stepping thread owns the simulation and the recording; nothing else touches them while
it runs. A service callback queues a function with `RequestQueue.call` and waits for its
future with `RequestQueue.wait`; the stepping thread runs queued functions between ticks
(`RequestQueue.serve`). Before the thread starts and after it ended, `call` runs the
function at once (nobody else touches the state then).
"""
from __future__ import annotations

import collections
import concurrent.futures
import threading
from typing import Any, Callable

from flexure_sim.engine.solver.simulation import SolverError
from flexure_sim.recording import RecordingError

#: How long a service waits for the stepping thread.
REQUEST_TIMEOUT_S = 30.0


def run_into(fn: Callable[[], Any], future: concurrent.futures.Future) -> None:
    """Run ``fn`` and put its result (or exception) into ``future``."""
    if not future.set_running_or_notify_cancel():
        return
    try:
        future.set_result(fn())
    except BaseException as exc:  # noqa: BLE001 - handed to the waiting caller
        future.set_exception(exc)


class RequestQueue:
    """Functions waiting for the stepping thread; ``wake`` is set whenever one is queued."""

    def __init__(self, thread_alive: Callable[[], bool]) -> None:
        self._items: collections.deque[tuple[Callable[[], Any], concurrent.futures.Future]] = \
            collections.deque()
        self._thread_alive = thread_alive
        self.wake = threading.Event()

    def __bool__(self) -> bool:
        return bool(self._items)

    def call(self, fn: Callable[[], Any]) -> concurrent.futures.Future:
        """Run ``fn`` in the stepping thread between ticks; the future holds its result."""
        future: concurrent.futures.Future = concurrent.futures.Future()
        if not self._thread_alive():
            run_into(fn, future)
            return future
        self._items.append((fn, future))
        self.wake.set()
        return future

    @staticmethod
    def wait(future: concurrent.futures.Future) -> tuple[bool, str]:
        """(success, message) of a queued call; an exception becomes its message."""
        try:
            result = future.result(timeout=REQUEST_TIMEOUT_S)
        except concurrent.futures.TimeoutError:
            return False, f"the stepping thread did not answer within {REQUEST_TIMEOUT_S:g} s"
        except (RecordingError, SolverError, OSError, ValueError) as exc:
            return False, str(exc)
        except Exception as exc:  # noqa: BLE001 - reported to the caller, the node stays up
            return False, f"{type(exc).__name__}: {exc}"
        if isinstance(result, tuple):
            return result
        return True, str(result) if result is not None else ""

    def run(self, fn: Callable[[], Any]) -> tuple[bool, str]:
        """`call` then `wait`."""
        return self.wait(self.call(fn))

    def serve(self) -> bool:
        """Run queued requests (stepping thread). Returns True if any ran."""
        ran = False
        while self._items:
            fn, future = self._items.popleft()
            run_into(fn, future)
            ran = True
        return ran

    def fail_all(self) -> None:
        """Fail whatever is still waiting (the stepping thread ends)."""
        while self._items:
            _, future = self._items.popleft()
            if not future.done():
                future.set_exception(RuntimeError("the node is shutting down"))
