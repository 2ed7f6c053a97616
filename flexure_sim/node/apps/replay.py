"""
``flexure-sim replay RUN.mcap`` (also ``ros2 run flexure_sim replay RUN.mcap``).

Publish the recorded topics again over ROS 2 with the recorded timing, and /clock, so that RViz,
Foxglove, PlotJuggler or your own nodes with ``use_sim_time`` see the run as it happened.

    flexure-sim replay runs/stage.mcap [-r RATE] [--start-offset S] [--loop]
                       [--topics T ...] [--exclude T ...] [--no-clock] [--clock-rate HZ]
                       [--wait-for-subscribers S] [--delay S] [--recover]

- Messages are published as recorded (the same CDR bytes), in log-time order, each at
  ``start + (log time - first log time) / RATE`` of the wall clock; a replay that cannot keep
  up publishes late but never out of order.
- Publishers use each topic's recorded QoS (reliability, durability, history, depth).
- /clock: a recording that holds /clock (stage_node in fast or lockstep mode) has it replayed
  as recorded; otherwise /clock is generated: one message at the log time of every message
  before it is published, and at ``--clock-rate`` Hz of the replayed time in between.
  ``--no-clock`` publishes no /clock at all. With ``--loop`` the clock jumps back at every
  pass (use_sim_time nodes see time go backwards, as with ``ros2 bag play --loop``).
- Replaying ``/drive/displacement`` while a stage_node runs drives that node: leave it out
  with ``--exclude /drive/displacement``.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import time
from typing import Any, Iterator, Optional, Sequence

from flexure_sim.console import quiet_pipe
from flexure_sim.node.release import release
from flexure_sim.recording.command_line import check_path, report_reading, tool_errors, warn
from flexure_sim.recording.ordered import OrderedLog
from flexure_sim.recording.exceptions import EXIT_OK, EXIT_USAGE, RunError
from flexure_sim.topics import CLOCK as CLOCK_TOPIC

PROG = "flexure-sim replay"
NODE_NAME = "flexure_sim_replay"
#: Longest sleep between checks for Ctrl-C and /clock fill-in (s).
MAX_SLEEP_S = 0.05
#: How long the end of a replay waits for reliable subscribers to acknowledge (s).
ACK_TIMEOUT_S = 2.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "run", metavar="RUN", help="recording of stage_node (or ros2 bag record): a bag "
        "directory (its files in order) or one MCAP file"
    )
    p.add_argument(
        "-r",
        "--rate",
        type=float,
        default=1.0,
        help="playback speed factor (default 1: recorded timing; 0.1: ten times slower)",
    )
    p.add_argument("--start-offset", type=float, default=0.0, metavar="S",
                   help="start this many seconds of log time into the recording (default 0)")
    p.add_argument(
        "-l",
        "--loop",
        action="store_true",
        help="play again from the start offset until interrupted",
    )
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="replay only these topics")
    p.add_argument(
        "--exclude", nargs="+", metavar="TOPIC", default=[], help="do not replay these topics"
    )
    p.add_argument(
        "--no-clock",
        action="store_true",
        help="publish no /clock (neither recorded nor generated)",
    )
    p.add_argument(
        "--clock-rate",
        type=float,
        default=100.0,
        metavar="HZ",
        help="generated /clock: rate of replayed time between messages (default 100; 0: only "
        "at message times)",
    )
    p.add_argument(
        "--wait-for-subscribers",
        type=float,
        default=0.0,
        metavar="S",
        help="before playing, wait up to S seconds until every replayed topic has a subscriber",
    )
    p.add_argument("--delay", type=float, default=0.0, metavar="S",
                   help="sleep S seconds after creating the publishers (lets discovery finish)")
    p.add_argument(
        "--recover",
        action="store_true",
        help="replay the readable part of a truncated or damaged file instead of failing",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no summary at the end")


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "replay",
        help="re-publish a recorded run over ROS 2 with its timing and /clock",
        description=__doc__.split("\n\n")[0].replace("``", ""),
    )
    add_arguments(p)
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    return tool_errors(PROG, lambda: play(args), can_recover=not args.recover)


@quiet_pipe
def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of the ``replay`` console script and of ``ros2 run flexure_sim replay``."""
    argv = list(sys.argv if argv is None else argv)
    try:
        from rclpy.utilities import remove_ros_args

        user_args = remove_ros_args(argv)[1:]
    except ImportError:
        user_args = argv[1:]
    parser = argparse.ArgumentParser(
        prog="replay", description=__doc__.split("\n\n")[0].replace("``", "")
    )
    add_arguments(parser)
    args = parser.parse_args(user_args)
    args.ros_argv = argv
    return run(args)


# ---------------------------------------------------------------------------- planning
def _check(args: argparse.Namespace) -> None:
    if not args.rate > 0 or args.rate == float("inf"):
        raise RunError(f"--rate {args.rate!r}: must be a positive number", EXIT_USAGE)
    if not args.start_offset >= 0:
        raise RunError(f"--start-offset {args.start_offset!r}: must be >= 0 seconds", EXIT_USAGE)
    if not args.clock_rate >= 0:
        raise RunError(f"--clock-rate {args.clock_rate!r}: must be >= 0 Hz", EXIT_USAGE)
    for name in ("wait_for_subscribers", "delay"):
        if not getattr(args, name) >= 0:
            raise RunError(
                f"--{name.replace('_', '-')} {getattr(args, name)!r}: must be >= 0 seconds",
                EXIT_USAGE,
            )


def plan(log: OrderedLog, topics: Optional[Sequence[str]], exclude: Sequence[str],
         start_offset: float, no_clock: bool) -> tuple[list[str], int, bool]:
    """Topics to publish, the log time to start at and whether /clock is generated."""
    available = sorted(log.topics)
    for option, names in (("--topics", topics or []), ("--exclude", exclude)):
        unknown = [t for t in names if t not in log.topics]
        if unknown:
            raise RunError(f"{option}: {', '.join(unknown)} not in {log.path} "
                           f"(topics: {', '.join(available)})", EXIT_USAGE)
    chosen = [t for t in available if (not topics or t in topics) and t not in exclude]
    if no_clock:
        chosen = [t for t in chosen if t != CLOCK_TOPIC]
    generate_clock = not no_clock and CLOCK_TOPIC not in chosen
    if not log.message_count:
        raise RunError(f"{log.path}: no messages to replay")
    start = log.start_ns + round(start_offset * 1e9)
    if next(log.messages(chosen, start), None) is None:
        raise RunError(f"{log.path}: no messages on the chosen topics after --start-offset "
                       f"{start_offset:g} s")
    return chosen, start, generate_clock


def _message_class(type_name: str) -> Any:
    pkg, _, name = type_name.partition("/msg/")
    if not name:
        pkg, _, name = type_name.partition("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _qos(topic_info: Any) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    profile = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
    if topic_info.qos:
        q = topic_info.qos[0]
        for attr, enum, value in (("reliability", ReliabilityPolicy, q.reliability),
                                  ("durability", DurabilityPolicy, q.durability),
                                  ("history", HistoryPolicy, q.history)):
            try:
                setattr(profile, attr, enum(enum.get_from_short_key(value)))
            except (KeyError, ValueError, TypeError):
                pass  # unknown policy: keep the default
        profile.depth = q.depth if q.depth > 0 else 100
    return profile


# ---------------------------------------------------------------------------- playing
def play(args: argparse.Namespace) -> int:
    _check(args)
    log = OrderedLog(check_path(args.run), recover=args.recover)
    if not log.complete and not log.message_count:
        raise RunError(f"{args.run}: nothing readable: {log.note}")
    report_reading(PROG, log)
    chosen, start_ns, generate_clock = plan(log, args.topics, args.exclude, args.start_offset,
                                            args.no_clock)

    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    rclpy.init(args=getattr(args, "ros_argv", None))
    node = None
    code = EXIT_OK
    try:
        node = rclpy.create_node(NODE_NAME)
        publishers: dict[str, Any] = {}
        for topic in chosen:
            type_name = log.topics[topic].type
            try:
                cls = _message_class(type_name)
            except (ImportError, AttributeError):
                warn(
                    PROG, f"{topic}: message type {type_name} is not installed here; not replayed"
                )
                continue
            publishers[topic] = node.create_publisher(cls, topic, _qos(log.topics[topic]))
        if not publishers:
            raise RunError(f"{args.run}: none of the chosen topics has an installed message type")
        clock_pub = None
        if generate_clock:
            clock_pub = node.create_publisher(
                Clock, CLOCK_TOPIC, QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                               durability=DurabilityPolicy.VOLATILE,
                                               history=HistoryPolicy.KEEP_LAST))
        everyone = list(publishers.values()) + ([clock_pub] if clock_pub else [])
        if args.wait_for_subscribers > 0:  # the replayed topics; a generated /clock is optional
            _wait_for_subscribers(node, list(publishers.values()), args.wait_for_subscribers)
        if args.delay > 0:
            _sleep_until(node, time.monotonic() + args.delay)
        player = _Player(node, publishers, clock_pub, args.rate, args.clock_rate)
        passes = 0
        wall0 = time.monotonic()
        while True:
            player.play(log.messages(list(publishers), start_ns))
            passes += 1
            if not args.loop or not node.context.ok():
                break
        wall = time.monotonic() - wall0
        if node.context.ok():
            for pub in everyone:
                if pub.qos_profile.reliability == ReliabilityPolicy.RELIABLE:
                    pub.wait_for_all_acked(rclpy.duration.Duration(seconds=ACK_TIMEOUT_S))
        if not args.quiet:
            span = player.span_s
            clock = ("/clock generated" if clock_pub else
                     "/clock as recorded" if CLOCK_TOPIC in publishers else "no /clock")
            print(
                f"replayed {player.published} message(s) on {len(publishers)} topic(s), "
                f"{span:.6g} s of "
                f"log time in {wall:.3g} s ({passes} pass(es), rate {args.rate:g}, {clock}; "
                f"at most {player.max_late_s * 1e3:.3g} ms late)"
            )
    except (KeyboardInterrupt, ExternalShutdownException):
        code = EXIT_OK  # Ctrl-C ends a replay, as it ends ros2 bag play
    finally:
        release(rclpy, node)
    return code


def _sleep_until(node: Any, deadline: float) -> None:
    while node.context.ok():
        left = deadline - time.monotonic()
        if left <= 0:
            return
        time.sleep(min(left, MAX_SLEEP_S))


def _wait_for_subscribers(node: Any, publishers: list, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while node.context.ok():
        missing = [p.topic_name for p in publishers if p.get_subscription_count() == 0]
        if not missing:
            return
        if time.monotonic() > deadline:
            shown = ", ".join(missing[:4]) + (
                f" and {len(missing) - 4} more" if len(missing) > 4 else ""
            )
            warn(PROG, f"no subscriber after {timeout:g} s on {shown}; playing anyway")
            return
        time.sleep(0.02)


class _Player:
    """Publishes messages at their recorded times (scaled by ``rate``) and the generated clock."""

    def __init__(self, node: Any, publishers: dict[str, Any], clock_pub: Any, rate: float,
                 clock_rate: float) -> None:
        from rosgraph_msgs.msg import Clock

        self.node = node
        self.publishers = publishers
        self.clock_pub = clock_pub
        self.rate = rate
        self.clock_period_ns = round(1e9 / clock_rate) if clock_rate > 0 else 0
        self.published = 0
        self.max_late_s = 0.0
        self.span_s = 0.0
        self._clock_msg = Clock()
        self._last_clock: Optional[int] = None

    def _clock(self, ns: int) -> None:
        stamp = self._clock_msg.clock
        stamp.sec, stamp.nanosec = divmod(ns, 1_000_000_000)
        self.clock_pub.publish(self._clock_msg)
        self._last_clock = ns

    def play(self, messages: Iterator[tuple[int, str, bytes]]) -> None:
        """Publish (log time ns, topic, payload) items, given in log-time order, on time."""
        t_first: Optional[int] = None
        wall0 = time.monotonic()
        rate = self.rate
        ok = self.node.context.ok
        self._last_clock = None
        for log_time_ns, topic, data in messages:
            if t_first is None:
                t_first, wall0 = log_time_ns, time.monotonic()
            self.span_s = max(self.span_s, (log_time_ns - t_first) / 1e9)
            target = wall0 + (log_time_ns - t_first) / 1e9 / rate
            while True:
                now = time.monotonic()
                if now >= target:
                    break
                if not ok():
                    return
                wait = min(target - now, MAX_SLEEP_S)
                if (
                    self.clock_pub is not None
                    and self.clock_period_ns
                    and self._last_clock is not None
                ):
                    # Fill the gap with clock ticks of the replayed time.
                    next_ns = self._last_clock + self.clock_period_ns
                    if next_ns < log_time_ns:
                        due = wall0 + (next_ns - t_first) / 1e9 / rate
                        if due <= now:
                            self._clock(next_ns)
                            continue
                        wait = min(wait, due - now)
                time.sleep(wait)
            late = time.monotonic() - target
            if late > self.max_late_s:
                self.max_late_s = late
            if not ok():
                return
            if self.clock_pub is not None and (
                    self._last_clock is None or log_time_ns > self._last_clock):
                self._clock(log_time_ns)
            self.publishers[topic].publish(data)
            self.published += 1


if __name__ == "__main__":
    sys.exit(main())
