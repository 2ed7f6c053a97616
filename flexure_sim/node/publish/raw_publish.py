"""
A tick's serialized messages handed to rclpy's own raw publish, the handles held once.

``rclpy.publisher.Publisher.publish(data)`` enters the publisher's handle (a use count that
defers the handle's destruction while a call runs), checks the type of ``data``, then calls
the handle's ``publish_raw``. That Python layer costs ~0.5 us a call, 13 us of a tick's 26
topics (measured with rclpy of Jazzy, Fast DDS, no subscriber: 26 ``publish(bytes)`` 28.5-29.0
us, the same bytes through the handles' ``publish_raw`` 15.9-16.3 us, ``with handle:`` around
each 24.0 us). The stepping thread publishes only CDR bytes it packed itself for each
publisher's own type, so the check is moot; it enters every handle once for as long as it
publishes (`TickPublishers.hold`), which defers a destruction exactly as the per-call ``with``
does, and calls ``publish_raw`` directly inside.

Publishers without such a handle (anything that is not an rclpy ``Publisher``) are called
through their ``publish``, as are all of them outside `TickPublishers.hold`.
"""
from __future__ import annotations

import contextlib
from typing import Any, Callable, Iterator, Sequence


def _raw_call(publisher: Any) -> tuple[Any, Callable[[bytes], Any]] | None:
    """Return an rclpy publisher's handle and its ``publish_raw``, or None (no such handle)."""
    handle = getattr(publisher, "handle", None)
    raw = getattr(handle, "publish_raw", None)
    if raw is None or not hasattr(handle, "__enter__") or not hasattr(handle, "__exit__"):
        return None
    return handle, raw


class TickPublishers:
    """
    The tick topics' publish calls: every topic (`full`) and the control topics (`control`).

    ``publishers``: one per tick topic in the topic table's order; ``control_indices``: the
    control topics' positions among them. Each call takes one message's serialized bytes.
    """

    def __init__(self, publishers: Sequence[Any], control_indices: Sequence[int]) -> None:
        self._publishers = list(publishers)
        self._control_indices = list(control_indices)
        self.held = False
        self._use([p.publish for p in self._publishers])

    def _use(self, calls: list[Callable[[Any], Any]]) -> None:
        self.full = calls
        self.control = [calls[i] for i in self._control_indices]

    @contextlib.contextmanager
    def hold(self) -> Iterator["TickPublishers"]:
        """
        Hold every rclpy publisher's handle while the block runs, and publish raw meanwhile.

        A handle that cannot be entered (the publisher already destroyed) keeps its
        ``publish``, which then raises as it would have.
        """
        with contextlib.ExitStack() as stack:
            calls = []
            for publisher in self._publishers:
                found = _raw_call(publisher)
                if found is None:
                    calls.append(publisher.publish)
                    continue
                handle, raw = found
                try:
                    stack.enter_context(handle)
                except Exception:  # noqa: BLE001 - rclpy's InvalidHandle: publish() says so
                    calls.append(publisher.publish)
                    continue
                calls.append(raw)
            self._use(calls)
            self.held = True
            try:
                yield self
            finally:
                self.held = False
                self._use([p.publish for p in self._publishers])
