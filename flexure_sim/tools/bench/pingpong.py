"""
The floor of a closed loop through rclpy on this machine: a bare ping-pong between two processes.

    python -m flexure_sim.tools.bench.pingpong --rate 2000 --duration 10 [--json]

The stage side is the stage node's closed loop without the stage: a thread paced as the
stepping thread is (``pacing.Pacer``, the node's default ``wake_spin`` and ``stepping_nice``)
that at every tick takes the answers waiting in a polled subscription (``stage.polled``, as the
node takes drive commands) and publishes a ping (std_msgs/Float64 holding the tick's number).
The controller side, another process (``--echo``), answers every ping it receives with the
same number from an rclpy callback, served as ``pi_controller`` serves its measurements
(``apps.answer_loop``; its measurement QoS: reliable, keep last 1). Figures as
``closed_loop``'s: ticks missed by the pacing, and how many answers were taken at the first
tick after their ping (a ping of tick k answered at tick k + 1 is "next tick"; each tick later
is one late tick). Whatever a stage node and a Python
controller do, a closed loop through rclpy on this machine cannot do better than this.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import struct
import subprocess
import sys
import threading
import time
from typing import Any, Optional, Sequence

from flexure_sim.node.params.table import STEPPING_NICE, WAKE_SPIN_S
from flexure_sim.node.stage.pacing import Pacer, set_thread_nice

#: Topics of the ping-pong (relative: a ROS namespace applies).
PING, PONG = "flexure_sim_ping", "flexure_sim_pong"
#: The node's defaults, as the stage side's pacing uses them.
DEFAULT_WAKE_SPIN_S = WAKE_SPIN_S
DEFAULT_NICE = STEPPING_NICE
_FLOAT64 = struct.Struct("<4sd")
_CDR_LE = b"\x00\x01\x00\x00"


def _qos(depth: int) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def echo() -> int:
    """Serve as the controller side: answer every ping with its number, until SIGINT."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from std_msgs.msg import Float64

    from flexure_sim.node.apps.answer_loop import AnswerLoop
    from flexure_sim.node.stage.polled import PolledGroup

    rclpy.init()
    node = rclpy.create_node("flexure_sim_pong")
    pong = node.create_publisher(Float64, PONG, _qos(1000))

    def answer(msg: Any) -> None:
        pong.publish(Float64(data=msg.data))

    ping = node.create_subscription(Float64, PING, answer, _qos(1), callback_group=PolledGroup())
    try:
        AnswerLoop(node, [(ping, answer)]).serve()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def run(rate: float, duration: float, wake_spin: float = DEFAULT_WAKE_SPIN_S,
        nice: int = DEFAULT_NICE, warmup: float = 2.0,
        domain_id: Optional[int] = None) -> dict[str, Any]:
    """Ping-pong at ``rate`` Hz for ``warmup`` + ``duration`` s; return the figures."""
    import rclpy
    from rclpy.context import Context
    from std_msgs.msg import Float64

    from flexure_sim.node.stage.polled import PolledGroup, never_called, take_raw

    domain = domain_id if domain_id is not None else random.randint(1, 100)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("flexure_sim_ping", context=context)
    child = subprocess.Popen([sys.executable, "-m", "flexure_sim.tools.bench.pingpong", "--echo"],
                             env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE)
    try:
        ping = node.create_publisher(Float64, PING, _qos(100))
        pong = node.create_subscription(Float64, PONG, never_called, _qos(1000), raw=True,
                                        callback_group=PolledGroup())
        deadline = time.monotonic() + 60.0
        while ping.get_subscription_count() == 0 or pong.get_publisher_count() == 0:
            if child.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("the echo process did not connect: "
                                   + child.stderr.read().decode(errors="replace")[-2000:])
            time.sleep(0.01)
        first = round(warmup * rate)
        ticks = first + round(duration * rate)
        period = 1.0 / rate
        late: list[int] = []
        out: dict[str, Any] = {}

        def paced() -> None:
            out["nice"] = set_thread_nice(nice)[0]
            pacer = Pacer(period, spin_s=min(wake_spin, period))
            pacer.start()
            missed = 0
            for k in range(ticks):
                pacer.wait()
                for data in take_raw(pong, 1000):
                    seq = int(_FLOAT64.unpack(data)[1])
                    if seq >= first:
                        late.append(k - seq - 1)
                ping.publish(_FLOAT64.pack(_CDR_LE, float(k)))
                if pacer.done() and k >= first:
                    missed += 1
            out["missed"] = missed

        thread = threading.Thread(target=paced, name="pingpong-paced")
        thread.start()
        thread.join()
    finally:
        child.terminate()
        try:
            child.wait(30)
        except subprocess.TimeoutExpired:
            child.kill()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    paced_ticks = ticks - first
    ordered = sorted(late)
    n = len(ordered)
    return {
        "rate": rate, "duration": duration, "wake_spin_s": min(wake_spin, period),
        "nice": out.get("nice"), "paced_ticks": paced_ticks, "missed_ticks": out.get("missed"),
        "missed_fraction": out["missed"] / paced_ticks if paced_ticks else None,
        "answers": n, "unanswered": paced_ticks - n,
        "applied_next_tick_fraction": sum(1 for v in late if v == 0) / n if n else None,
        "late_ticks_p99": ordered[min(n - 1, int(0.99 * n))] if n else None,
        "late_ticks_max": ordered[-1] if n else None,
    }


def summary(r: dict[str, Any]) -> str:
    """One line of the figures."""
    def pct(v: Optional[float]) -> str:
        return "n/a" if v is None else f"{100 * v:.2f} %"
    return (f"rclpy ping-pong at {r['rate'] / 1e3:g} kHz (no simulation, no recording): missed "
            f"ticks {pct(r['missed_fraction'])}, answered at the next tick "
            f"{pct(r['applied_next_tick_fraction'])} (late ticks p99 {r['late_ticks_p99']}, "
            f"max {r['late_ticks_max']}; {r['unanswered']} of {r['paced_ticks']} unanswered)")


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m flexure_sim.tools.bench.pingpong",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--rate", type=float, default=1000.0, help="ticks per second")
    parser.add_argument("--duration", type=float, default=10.0, help="measuring window, s")
    parser.add_argument("--wake-spin", type=float, default=DEFAULT_WAKE_SPIN_S,
                        help="busy-wait before each tick, s (the node's wake_spin)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--echo", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.echo:
        return echo()
    r = run(args.rate, args.duration, args.wake_spin)
    print(json.dumps(r) if args.json else summary(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
