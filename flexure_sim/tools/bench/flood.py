"""
A drive-command flood from a process of its own, as a misbehaving controller would send it.

    python -m flexure_sim.tools.bench.flood --rate 10000 --duration 10 [--json]

Publishes ``std_msgs/Float64`` commands on ``drive/displacement`` (the node's command QoS:
reliable, keep last ``command_depth``'s default) at ``--rate`` Hz for ``--duration`` s,
alternating between two values inside the stage's stroke, and waits (up to ``ACK_WAIT_S``)
until the node acknowledged them all before it quits, so that what the node did not record is
what the node lost (counted in its ``commands_lost``), not a tail still in the publisher.
It waits for the node's subscription first (up to 30 s), follows an absolute schedule (it
catches up with bursts after a late wake-up, so the mean rate holds) and publishes
pre-serialized bytes, so the flood itself costs as little CPU as rclpy allows.
``tools/bench/measure.py --flood`` runs it next to the node; ``bench --node`` reports the result.
"""
from __future__ import annotations

import argparse
import json
import select
import struct
import subprocess
import sys
import time
from typing import Any, Callable, Optional, Sequence

from flexure_sim import topics

#: Commands (m) the flood alternates between: inside the stage's 0..2 um stroke.
VALUES = (1.0e-6, 1.5e-6)
#: Line printed (with --json) when the flood begins.
STARTED = '{"started": true}'
#: Longest sleep between bursts (s).
SLEEP_S = 5e-4
#: Longest wait for the node to acknowledge the last commands (s).
ACK_WAIT_S = 10.0


def flood(rate: float, duration: float, topic: str = topics.COMMAND, wait_s: float = 30.0,
          started: Optional[Callable[[], None]] = None) -> dict[str, Any]:
    """
    Publish at ``rate`` Hz for ``duration`` s once a subscriber matched; return the counts.

    ``started`` is called when the subscriber matched.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.duration import Duration
    from std_msgs.msg import Float64

    from flexure_sim.node.publish.interface import command_qos

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("flexure_sim_flood", context=context)
    try:
        publisher = node.create_publisher(Float64, topic, command_qos())
        deadline = time.monotonic() + wait_s
        while publisher.get_subscription_count() == 0:
            if time.monotonic() > deadline:
                raise RuntimeError(f"no subscriber of {topic} within {wait_s:g} s")
            time.sleep(0.01)
        payloads = [b"\x00\x01\x00\x00" + struct.pack("<d", v) for v in VALUES]
        if started is not None:
            started()
        publish = publisher.publish
        period = 1.0 / rate
        sent = 0
        t0 = time.perf_counter()
        end = t0 + duration
        while (now := time.perf_counter()) < end:
            due = int((now - t0) / period) + 1
            while sent < due:
                publish(payloads[sent & 1])
                sent += 1
            time.sleep(SLEEP_S)
        wall = time.perf_counter() - t0
        acked = publisher.wait_for_all_acked(Duration(seconds=ACK_WAIT_S))
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return {"rate_hz": rate, "sent": sent, "wall_s": wall, "sent_per_s": sent / wall,
            "all_acked": bool(acked)}


class FloodProcess:
    """
    `flood` in a process of its own (this interpreter, environment ``env``), for measure.py.

    `wait_started` until it floods, `result` when it ended.
    """

    def __init__(self, rate: float, duration: float, env: dict[str, str]) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "flexure_sim.tools.bench.flood", "--rate", repr(rate),
             "--duration", repr(duration), "--json"],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

    def wait_started(self, idle: Callable[[], None], timeout: float = 60.0) -> None:
        """Call ``idle`` (e.g. spin an executor briefly) until the flood has begun."""
        deadline = time.monotonic() + timeout
        stdout = self.proc.stdout
        while time.monotonic() < deadline:
            if select.select([stdout], [], [], 0.0)[0]:
                line = stdout.readline()
                if line.strip() == STARTED:
                    return
                if not line:
                    break
            idle()
        raise RuntimeError("the command flood did not start")

    def result(self, timeout: float = 60.0) -> dict[str, Any]:
        """Return the flood's JSON summary (it ends on its own)."""
        out, _ = self.proc.communicate(timeout=timeout)
        lines = [line for line in out.splitlines() if line.startswith("{")]
        if self.proc.returncode != 0 or not lines:
            raise RuntimeError(f"the command flood failed ({self.proc.returncode}): "
                               f"{out.strip()}")
        return json.loads(lines[-1])


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m flexure_sim.tools.bench.flood",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--rate", type=float, default=10000.0, help="commands per second")
    parser.add_argument("--duration", type=float, default=10.0, help="seconds of flood")
    parser.add_argument("--topic", default=topics.COMMAND)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if not (args.rate > 0 and args.duration > 0):
        parser.error("--rate and --duration must be > 0")
    try:
        result = flood(args.rate, args.duration, args.topic,
                       started=lambda: print(STARTED, flush=True) if args.json else None)
    except (RuntimeError, KeyboardInterrupt) as exc:
        print(f"flood: {exc or 'interrupted'}", file=sys.stderr)
        return 1
    print(json.dumps(result) if args.json else
          f"sent {result['sent']} commands in {result['wall_s']:.2f} s "
          f"({result['sent_per_s']:.0f}/s) on {args.topic}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
