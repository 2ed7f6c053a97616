"""
Subscriptions read by the stepping thread at each tick instead of by the executor.

Every executor wake-up costs the node ~0.4 ms of GIL time: rclpy rebuilds its wait set in
Python from every entity of the node, and the node's ~26 publishers each bring QoS event
handlers. A controller publishing drive commands at 1 kHz would wake the executor every
millisecond, and that GIL time would land on the paced stepping thread as late ticks.

A subscription created in a `PolledGroup` is never put in the executor's wait set (rclpy's
executors only wait on entities whose callback group ``can_execute`` them), so commands do
not wake the executor at all. It stays an ordinary subscription of the node: same name
resolution and remapping, listed by ``ros2 node info``, matched with the same QoS. The
stepping thread takes what the reader holds with `take_raw` once per tick.

`take_raw` calls ``take_message`` on the subscription's ``handle``: the object rclpy's own
executors take messages with, not a documented API. rclpy (Jazzy) has no public way to take
a message outside an executor. The public way, a node of its own holding the subscription in
an executor the stepping thread spins for no time at each tick
(``SingleThreadedExecutor.spin_once(timeout_sec=0)``), cost 54 us of thread CPU time per tick
with nothing waiting and 36 us to receive one command, against 0.9 us and 6.4 us for
`take_raw` (same process, one measurement, 2-core VM under load): a quarter of the node's
whole tick. If rclpy changes ``take_message``, test_node_polled.py fails.
"""
from __future__ import annotations

from typing import Any, Optional

from rclpy.callback_groups import CallbackGroup
from rclpy.exceptions import InvalidHandle
from rclpy.subscription import Subscription


class PolledGroup(CallbackGroup):
    """A callback group whose entities the executor never waits on nor runs."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


def never_called(_message: Any) -> None:
    """
    Serve as the callback of a polled subscription.

    rclpy requires one; the executor never runs it.
    """


def take_raw(subscription: Subscription, limit: int,
             numbers: Optional[list[Optional[int]]] = None) -> list[bytes]:
    """
    Up to ``limit`` serialized messages waiting in ``subscription``'s reader.

    Oldest first (the rest stay for the next call). Empty once the node is being destroyed.
    ``numbers``: a list to which each message's publication sequence number is appended (from
    the message info ``take_message`` returns with it; None where the middleware has none).
    """
    taken: list[bytes] = []
    try:
        with subscription.handle:
            take = subscription.handle.take_message
            msg_type = subscription.msg_type
            for _ in range(limit):
                item = take(msg_type, True)
                if item is None:
                    break
                taken.append(item[0])
                if numbers is not None:
                    numbers.append(item[1].get("publication_sequence_number"))
    except InvalidHandle:
        pass
    return taken
