"""
Incompatible QoS on the stage node's topics: counted, logged, shown in the diagnostics.

A DDS reader and writer whose QoS do not match never exchange a message, and nothing else
says so. The node therefore handles rmw's incompatible-QoS events:

- on the drive command subscription (a publisher the node cannot hear, e.g. a best-effort
  one while ``command_reliability`` is ``reliable``): WARN naming the policy and the remedy;
- on every published topic (a subscriber the node cannot serve, e.g. one asking for
  transient-local durability): WARN naming the topic and the policy.

The command subscription is polled by the stepping thread and its callback group is never
served by the executor (`polled`); its QoS event handlers would put the reader in the
executor's wait set (which then holds it while it waits, and made the stepping thread lose
commands in a flood). Incompatible command publishers are therefore found by a graph check
(`check_command_publishers`; traced in the node next to a controller: 0.19 ms median, 0.29 ms
at most) that the stepping thread runs itself every `GRAPH_CHECK_PERIOD_S` after a tick's
work, so that it delays the next tick only after a tick of over 0.7 ms at 1 kHz. It used to run
on a 0.5 s executor timer: each wake-up of the executor took the GIL from the paced stepping
thread, and in real time at 1 kHz that was most of the node's missed ticks (15 s quiet runs:
17-27 missed with the timer, 0 and 0 without it; BENCHMARKS.md).
Counts appear in the diagnostics (`qos_incompatible_publishers`, `..._subscribers`, WARN in
the window in which one appeared).
"""
from __future__ import annotations

from typing import Any, Callable, Optional

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.qos import qos_policy_name_from_kind

from flexure_sim.node.publish import interface as itf

#: Wall-clock period of the command publishers' graph check (s): a best-effort publisher is
#: warned about within about this long of appearing.
GRAPH_CHECK_PERIOD_S = 0.5


class QosWatch:
    """
    Counters and WARN lines of incompatible-QoS events (executor thread).

    Read by the diagnostics (stepping thread).
    """

    def __init__(self, log: Any, command_reliability: str) -> None:
        self._log = log
        self.command_reliability = command_reliability
        self.publishers = 0
        self.subscribers = 0
        self._reported = (0, 0)
        self._best_effort_seen = 0

    # ------------------------------------------------------------- callbacks
    def publisher_callbacks(self, topic: str,
                            matched: Optional[Callable[[Any], None]] = None
                            ) -> PublisherEventCallbacks:
        """Return the publisher's event callbacks: incompatible QoS, and ``matched`` if given."""
        def incompatible(event: Any) -> None:
            self.subscribers += max(int(getattr(event, "total_count_change", 1)), 1)
            policy = qos_policy_name_from_kind(event.last_policy_kind)
            self._log.warning(
                f"a subscriber of {topic} requests QoS this node does not offer ({policy}): "
                f"it receives nothing (the node publishes reliable, volatile); "
                f"{self.subscribers} such subscribers so far")
        return PublisherEventCallbacks(incompatible_qos=incompatible, matched=matched)

    def check_command_publishers(self, node: Any, topic: str) -> None:
        """
        Count best-effort publishers on the command topic that a reliable subscription ignores.

        A graph check, run by the stepping thread between ticks (module doc): the
        subscription's own QoS events would put the polled reader in the executor's wait set.
        """
        if self.command_reliability != "reliable":
            return
        from rclpy.qos import ReliabilityPolicy

        best_effort = sum(1 for info in node.get_publishers_info_by_topic(topic)
                          if info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT)
        if best_effort > self._best_effort_seen:
            self.publishers += best_effort - self._best_effort_seen
            self._log.warning(
                f"a publisher on {topic} offers QoS incompatible with the command subscription "
                "(RELIABILITY): none of its commands reach the node (it publishes best effort? "
                "set command_reliability:=best_effort, or publish reliable); "
                f"{self.publishers} such publishers so far")
        self._best_effort_seen = best_effort

    # ------------------------------------------------------------ diagnostics
    def diagnostics(self) -> tuple[list[tuple[str, Any]], list[str], int]:
        """(values, notes, level) for the diagnostics window ending now."""
        publishers, subscribers = self.publishers, self.subscribers
        new_p, new_s = publishers - self._reported[0], subscribers - self._reported[1]
        self._reported = (publishers, subscribers)
        notes = []
        if new_p:
            notes.append(f"{new_p} command publishers with incompatible QoS")
        if new_s:
            notes.append(f"{new_s} subscribers with incompatible QoS")
        values = [("command_reliability", self.command_reliability),
                  ("qos_incompatible_publishers", publishers),
                  ("qos_incompatible_subscribers", subscribers)]
        return values, notes, itf.WARN if notes else itf.OK
