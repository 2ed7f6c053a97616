"""
Releasing rclpy at a process's exit within a deadline (no ROS import here).

Releasing a node can hang in the middleware: in one CI run a ``stage_node`` that failed to
start spun for 35 min (one core busy, nothing printed) in Fast DDS 2.14's
``DomainParticipant::set_listener`` under ``rcl_node_fini``, which waits for an in-flight
discovery callback while that callback waited for the mutex the spinning thread kept taking
(eight node processes starting at once on one domain; eProsima/Fast-DDS#6513 describes the
spin). The spinning thread holds the GIL, so no Python thread can end it: `exit_deadline`
arms faulthandler's watchdog, a C thread.
"""
from __future__ import annotations

import contextlib
import faulthandler
import sys
from typing import Any, Iterator, Optional

#: Seconds the middleware may take to release a process's nodes at exit.
EXIT_GRACE_S = 10.0


@contextlib.contextmanager
def exit_deadline(seconds: float) -> Iterator[None]:
    """
    End the process with exit code 1 if the block takes longer than ``seconds`` (module doc).

    faulthandler's watchdog, a C thread, then writes every thread's stack to stderr and exits.
    """
    try:
        faulthandler.dump_traceback_later(seconds, exit=True, file=sys.stderr)
    except (AttributeError, ValueError, OSError):  # a stderr without a file descriptor
        faulthandler.dump_traceback_later(seconds, exit=True, file=sys.__stderr__)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()


def release(rclpy: Any, node: Optional[Any] = None) -> None:
    """Destroy ``node`` (if any) and shut ``rclpy`` down within `EXIT_GRACE_S` (module doc)."""
    with exit_deadline(EXIT_GRACE_S):
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
