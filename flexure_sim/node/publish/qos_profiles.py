"""
The QoS profiles of the stage node's topics (docs/node.md, "QoS").

Every published stream is reliable, keep last `QUEUE_DEPTH`, volatile; the drive command
subscriptions keep ``command_depth`` (default `COMMAND_DEPTH`) and are reliable or
best-effort (``command_reliability``); ``~/ready`` is latched (`READY_QOS`).
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# Default depth of the drive command subscription (parameter command_depth).
from flexure_sim.node.params.table import COMMAND_DEPTH

#: Depth of every published stream.
QUEUE_DEPTH = 100


#: ``~/ready``: reliable, transient local, the last message kept (a latched topic).
READY_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                       reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _reliable_volatile(depth: int) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def stream_qos() -> QoSProfile:
    """Return the QoS of every published topic: reliable, keep last `QUEUE_DEPTH`, volatile."""
    return _reliable_volatile(QUEUE_DEPTH)


def command_qos(reliability: str = "reliable", depth: int = COMMAND_DEPTH) -> QoSProfile:
    """
    Return the QoS of the drive command subscription.

    ``reliability`` (``reliable``: only reliable publishers match; ``best_effort``: reliable and
    best-effort ones), keep last ``depth`` (parameter ``command_depth``), volatile.

    The reader is emptied once per tick (`polled`), so it must hold a tick's worth of
    commands: the default 10000 is 1 s of a 10 kHz stream (ticks down to 1 Hz, or a stall of
    the node of up to 1 s); what it cannot hold is counted (`command_loss`).
    """
    qos = _reliable_volatile(depth)
    if reliability == "best_effort":
        qos.reliability = ReliabilityPolicy.BEST_EFFORT
    elif reliability != "reliable":
        raise ValueError(f"reliability: expected reliable or best_effort, got {reliability!r}")
    return qos
