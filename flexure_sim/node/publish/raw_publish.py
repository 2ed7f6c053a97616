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

Only topics with a subscriber are published (`TickPublishers.set_subscribed`, fed by the
publishers' matched events): the tick topics are volatile, so a reader that is not there is
owed nothing, and Fast DDS takes ~0.8 us a message even with nobody to send it to (26 topics:
18-21 us a tick, against a 45-60 us tick without them; BENCHMARKS.md). A controller
subscribes to one or two of them.
Every topic is recorded whoever subscribes.
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


def _subscription_count(publisher: Any) -> int:
    """Return an rclpy publisher's subscription count; 1 for other publishers (always sent)."""
    count = getattr(publisher, "get_subscription_count", None)
    if count is None:
        return 1
    try:
        return int(count())
    except Exception:  # noqa: BLE001 - a destroyed publisher: publish() will say so
        return 1


class TickPublishers:
    """
    The tick topics' publish calls: every topic (`full`) and the control topics (`control`).

    ``publishers``: one per tick topic in the topic table's order; ``control_indices``: the
    control topics' positions among them. `full` and `control` hold ``(k, call)`` of the topics
    with a subscriber: ``call`` takes the serialized bytes of the ``k``-th message of the tick
    (of all topics, or of the control topics). `subscribed` starts from each rclpy publisher's
    subscription count (True for other publishers).
    """

    def __init__(self, publishers: Sequence[Any], control_indices: Sequence[int]) -> None:
        self._publishers = list(publishers)
        self._control_indices = list(control_indices)
        self.held = False
        #: Per topic: whether it has a subscriber (written by the executor thread).
        self.subscribed = [_subscription_count(p) > 0 for p in self._publishers]
        self._version = self._built = 0
        self._use([p.publish for p in self._publishers])

    def _use(self, calls: list[Callable[[Any], Any]]) -> None:
        self._calls = calls
        self._built = version = self._version
        subscribed = list(self.subscribed)
        self.full = [(k, call) for k, call in enumerate(calls) if subscribed[k]]
        self.control = [(j, calls[k]) for j, k in enumerate(self._control_indices)
                        if subscribed[k]]
        if self._version != version:  # changed meanwhile: build again at the next `current`
            self._built = -1

    def set_subscribed(self, index: int, subscribed: bool) -> None:
        """Topic ``index`` has (or no longer has) a subscriber; any thread."""
        if self.subscribed[index] != subscribed:
            self.subscribed[index] = subscribed
            self._version += 1

    def refresh(self) -> None:
        """Take every rclpy publisher's subscription count now (lockstep ticks)."""
        for k, publisher in enumerate(self._publishers):
            self.set_subscribed(k, _subscription_count(publisher) > 0)

    def current(self, monitor: bool) -> list[tuple[int, Callable[[Any], Any]]]:
        """`full` (``monitor``) or `control`, rebuilt first if a topic's subscribers changed."""
        if self._built != self._version:
            self._use(self._calls)
        return self.full if monitor else self.control

    @property
    def subscribed_count(self) -> int:
        """How many tick topics have a subscriber."""
        return sum(self.subscribed)

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
