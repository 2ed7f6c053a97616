"""
The QoS profiles of the stage node's topics (docs/node.md, "QoS").

Every published stream is reliable, keep last `QUEUE_DEPTH`, volatile; the drive command
subscriptions keep `COMMAND_DEPTH` and are reliable or best-effort (``command_reliability``).
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

#: Depth of every published stream.
QUEUE_DEPTH = 100
#: Depth of the drive command subscription (commands waiting for the next tick).
COMMAND_DEPTH = 1000


def _reliable_volatile(depth: int) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def stream_qos() -> QoSProfile:
    """Return the QoS of every published topic: reliable, keep last `QUEUE_DEPTH`, volatile."""
    return _reliable_volatile(QUEUE_DEPTH)


def command_qos(reliability: str = "reliable") -> QoSProfile:
    """
    Return the QoS of the drive command subscription.

    ``reliability`` (``reliable``: only reliable publishers match; ``best_effort``: reliable and
    best-effort ones), keep last `COMMAND_DEPTH`, volatile.

    The reader is emptied once per tick (`polled`), so it must hold a tick's worth of
    commands: 1000 is a 1 MHz stream at 1 kHz ticks, or 200 ms of a 5 kHz stream at 5 Hz.
    """
    qos = _reliable_volatile(COMMAND_DEPTH)
    if reliability == "best_effort":
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
    elif reliability != "reliable":
        raise ValueError(f"reliability: expected reliable or best_effort, got {reliability!r}")
    return qos
