"""
A small rclpy node that drives a running ``stage_node`` through a demo profile of steps.

It optionally records exactly that part of the run, and reports the gain it saw live.

    python -m flexure_sim.node.apps.demo_drive [--fractions 0.25 0.5 0.75 1 0 | --levels M ...]
        [--rest 0.01] [--dwell 0.02] [--node stage_node] [--record] [--json] [--timeout 60]

Profile: at rest for ``--rest`` s, then each level for ``--dwell`` s. By default the levels are
fractions of the stage's stroke read from the node's parameters (stroke_min, stroke_max):
0.25, 0.5, 0.75, 1 (full stroke) and back to 0 -- 0 -> 0.5 -> 1.0 -> 1.5 -> 2.0 -> 0 um for the
built-in stage.

Time, by the node's ``time_mode``: in lockstep mode the driver advances the node tick by tick
with ``~/step`` (std_srvs/Trigger), so every command lands on its tick and every run gives the
same numbers, whatever the machine's load; in fast mode it follows /clock (commands land as
soon as the node takes them, which a busy machine delays); in realtime mode the wall clock.

``--record`` turns the node's recording on (``~/record``, std_srvs/SetBool) just before the
profile and off after it, so the file holds the demo and nothing else; the path is printed.

Live gain of a step: (output change) / (drive input change) between the last values received
before the step and before the next one (or the end). ``flexure-sim analyse`` of the recording
must give the same numbers.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any, Optional, Sequence

from flexure_sim.errors import FlexureSimError
from flexure_sim import topics
from flexure_sim.node.release import release

PROG = "demo_drive"
NODE_NAME = "flexure_sim_demo_drive"
DEFAULT_FRACTIONS = (0.25, 0.5, 0.75, 1.0, 0.0)


class DriveError(FlexureSimError, RuntimeError):
    """The demo cannot run (no stage node, no clock progress...); the message says why."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0].replace("``", ""))
    g = p.add_mutually_exclusive_group()
    g.add_argument("--levels", nargs="+", type=float, metavar="M", help="command levels in metres")
    g.add_argument("--fractions", nargs="+", type=float, metavar="F",
                   help="levels as fractions of the node's stroke (default 0.25 0.5 0.75 1 0)")
    p.add_argument(
        "--rest",
        type=float,
        default=0.01,
        help="time at rest before the first step (s, default 0.01)",
    )
    p.add_argument(
        "--dwell", type=float, default=0.02, help="time at each level (s, default 0.02)"
    )
    p.add_argument(
        "--node", default="stage_node", help="name of the stage node (default stage_node)"
    )
    p.add_argument("--record", action="store_true",
                   help="record exactly the profile (the node's ~/record service on, then off)")
    p.add_argument("--json", action="store_true", help="print the live values as one JSON object")
    p.add_argument("--timeout", type=float, default=60.0,
                   help="give up when the node does not answer or time stops for this long (s)")
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    argv = list(sys.argv if argv is None else argv)
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.utilities import remove_ros_args

    args = build_parser().parse_args(remove_ros_args(argv)[1:])
    for name in ("rest", "dwell", "timeout"):
        value = getattr(args, name)
        if not (value > 0 and math.isfinite(value)):
            print(
                f"{PROG}: error: --{name} {value!r}: must be a positive number of seconds",
                file=sys.stderr,
            )
            return 2
    rclpy.init(args=argv)
    driver = None
    code = 0
    try:
        driver = DemoDriver(args)
        result = driver.run()
        if args.json:
            print(json.dumps(result))
        else:
            print(format_live(result))
    except DriveError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        code = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        code = 130
    finally:
        release(rclpy, driver)
    return code


def format_live(result: dict) -> str:
    lines = [f"demo profile on {result['node']} ({result['time_source']} time): "
             f"{len(result['steps'])} step(s)"]
    for s in result["steps"]:
        gain = "-" if s["gain"] is None else f"{s['gain']:.6g}"
        lines.append(
            f"  step {s['index']}: t = {s['t'] * 1e3:9.3f} ms, command "
            f"{s['command_before'] * 1e6:g} -> "
            f"{s['command'] * 1e6:g} um, output {s['output'] * 1e6:.5g} um, live gain {gain}"
        )
    if result.get("recording"):
        lines.append(f"recorded to {result['recording']}")
    return "\n".join(lines)


def _qos(depth: int = 100):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


class DemoDriver:
    """The driving node (composition keeps rclpy imports out of module import time)."""

    def __init__(self, args: argparse.Namespace) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Float64

        self.args = args
        self.node = rclpy.create_node(NODE_NAME)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.pub = self.node.create_publisher(Float64, topics.COMMAND, _qos())
        self.clock_ns: Optional[int] = None
        self.output: Optional[float] = None
        self.input: Optional[float] = None
        self.node.create_subscription(Clock, "/clock", self._on_clock, _qos(10))
        self.node.create_subscription(Float64, topics.OUTPUT, self._on_output, _qos())
        self.node.create_subscription(Float64, "drive/input", self._on_input, _qos())
        self._Float64 = Float64
        self._counter = {"output": 0, "input": 0}

    def destroy_node(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()

    # ------------------------------------------------------------------ callbacks
    def _on_clock(self, msg: Any) -> None:
        self.clock_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec

    def _on_output(self, msg: Any) -> None:
        self.output = msg.data
        self._counter["output"] += 1

    def _on_input(self, msg: Any) -> None:
        self.input = msg.data
        self._counter["input"] += 1

    # ------------------------------------------------------------------ helpers
    def _spin_until(self, predicate, what: str, timeout: Optional[float] = None) -> None:
        timeout = self.args.timeout if timeout is None else timeout
        end = time.monotonic() + timeout
        while not predicate():
            if not self.node.context.ok():
                raise DriveError("interrupted")
            if time.monotonic() > end:
                raise DriveError(f"timed out after {timeout:g} s waiting for {what}")
            self.executor.spin_once(timeout_sec=0.005)

    def _service_name(self, suffix: str) -> str:
        node = self.args.node
        base = node if node.startswith("/") else f"{self.node.get_namespace().rstrip('/')}/{node}"
        return f"{base}/{suffix}"

    def _call(self, srv_type: Any, name: str, request: Any) -> Any:
        client = self.node.create_client(srv_type, name)
        try:
            self._spin_until(
                client.service_is_ready, f"the service {name} (is {self.args.node} running?)"
            )
            future = client.call_async(request)
            self._spin_until(future.done, f"the answer of {name}")
            return future.result()
        finally:
            self.node.destroy_client(client)

    def _parameters(self) -> dict[str, Any]:
        """stroke_min, stroke_max, time_mode and publish_rate of the stage node."""
        from rcl_interfaces.srv import GetParameters

        name = self._service_name("get_parameters")
        keys = ["stroke_min", "stroke_max", "publish_rate", "time_mode"]
        answer = self._call(GetParameters, name, GetParameters.Request(names=keys))
        if len(answer.values) != len(keys):
            raise DriveError(f"{name} did not return {', '.join(keys)}")
        v = answer.values
        params = {"stroke_min": v[0].double_value, "stroke_max": v[1].double_value,
                  "publish_rate": v[2].double_value, "time_mode": v[3].string_value}
        if (
            not all(math.isfinite(params[k]) for k in ("stroke_min", "stroke_max", "publish_rate"))
            or params["publish_rate"] <= 0
        ):
            raise DriveError(f"{name} returned unusable values {params}")
        return params

    def _record(self, on: bool) -> str:
        from std_srvs.srv import SetBool

        name = self._service_name("record")
        answer = self._call(SetBool, name, SetBool.Request(data=on))
        if not answer.success:
            raise DriveError(
                f"{name} refused to turn recording {'on' if on else 'off'}: {answer.message}"
            )
        return answer.message

    # ------------------------------------------------------------------ the profile
    def run(self) -> dict:
        args = self.args
        params = self._parameters()
        if args.levels is not None:
            levels = list(args.levels)
        else:
            lo, hi = params["stroke_min"], params["stroke_max"]
            levels = [lo + f * (hi - lo) for f in (args.fractions or DEFAULT_FRACTIONS)]
        # The command subscription of the stage node must be matched before the first step.
        self._spin_until(lambda: self.pub.get_subscription_count() > 0,
                         f"a subscriber of {self.pub.topic_name} (is {args.node} running?)")
        lockstep = params["time_mode"] == "lockstep"
        recording = ""
        if lockstep:
            if args.record:
                recording = _recorded_path(self._record(True))
            seen, source = self._run_lockstep(levels, 1.0 / params["publish_rate"]), "lockstep"
        else:
            self._spin_until(lambda: self.output is not None and self.input is not None,
                             "output/displacement and drive/input")
            if args.record:
                recording = _recorded_path(self._record(True))
            seen, source = self._run_timed(levels)
        if args.record:
            self._record(False)
        steps = []
        previous = seen[0]["input"]
        for i, level in enumerate(levels):
            before, after = seen[i], seen[i + 1]
            du = after["input"] - before["input"]
            steps.append({
                "index": i + 1, "t": before["t"], "command_before": previous, "command": level,
                "input_before": before["input"], "input": after["input"],
                "output_before": before["output"], "output": after["output"],
                "gain": (after["output"] - before["output"]) / du if du else None,
            })
            previous = level
        return {"node": args.node, "time_source": source, "levels": levels, "steps": steps,
                "recording": recording}

    def _run_lockstep(self, levels: list[float], period: float) -> list[dict]:
        """
        Advance a lockstep node tick by tick with ~/step: exact, reproducible timing.

        Before each command the values of the last tick are awaited (the node publishes every
        topic once per tick), so the live values are those of a known tick.
        """
        from std_srvs.srv import Trigger

        name = self._service_name("step")
        client = self.node.create_client(Trigger, name)
        counts = {"output": 0, "input": 0}
        self._counter = counts
        ticks = 0
        t_ns = 0

        def step(n: int) -> None:
            nonlocal ticks, t_ns
            for _ in range(n):
                if not self.node.context.ok():
                    raise DriveError("interrupted")
                future = client.call_async(Trigger.Request())
                self._spin_until(future.done, f"the answer of {name}")
                answer = future.result()
                if not answer.success:
                    raise DriveError(f"{name} failed: {answer.message}")
                ticks += 1
                try:  # the node answers "t = <sim time> s"
                    t_ns = round(float(answer.message.split("=")[1].split()[0]) * 1e9)
                except (IndexError, ValueError):
                    t_ns = round(ticks * period * 1e9)

        def settled_values() -> dict:
            self._spin_until(lambda: counts["output"] >= ticks and counts["input"] >= ticks,
                             "the messages of the last tick")
            return {"t": t_ns / 1e9, "input": self.input, "output": self.output}

        try:
            self._spin_until(client.service_is_ready, f"the service {name}")
            n_rest = max(1, round(self.args.rest / period))
            n_dwell = max(1, round(self.args.dwell / period))
            step(n_rest)
            seen = []
            for level in levels:
                before = settled_values()
                seen.append(before)
                self.pub.publish(self._Float64(data=float(level)))
                # The command normally reaches the node before the next ~/step request; if it
                # was late, the input has not moved: step on until it does, so that every
                # level is held for the full dwell after it was applied.
                taken = 0
                while True:
                    step(1)
                    taken += 1
                    if settled_values()["input"] != before["input"] or level == before["input"]:
                        break
                    if taken * period > self.args.timeout:
                        raise DriveError(f"the node did not apply the command {level:g} m")
                step(max(0, n_dwell - 1))
            seen.append(settled_values())
            return seen
        finally:
            self.node.destroy_client(client)

    def _run_timed(self, levels: list[float]) -> tuple[list[dict], str]:
        """Publish the levels at their times on /clock (or the wall clock without /clock)."""
        args = self.args
        node = self.node
        use_sim = node.count_publishers("/clock") > 0
        if use_sim:
            self._spin_until(lambda: self.clock_ns is not None, "/clock")

        def now_ns() -> int:
            return self.clock_ns if use_sim else time.monotonic_ns()

        start = now_ns()
        times = [start + round((args.rest + k * args.dwell) * 1e9) for k in range(len(levels) + 1)]
        seen: list[dict] = []
        last_progress = (now_ns(), time.monotonic())
        k = 0
        while k <= len(levels):
            self.executor.spin_once(timeout_sec=0.002)
            if not node.context.ok():
                raise DriveError("interrupted")
            t = now_ns()
            if t != last_progress[0]:
                last_progress = (t, time.monotonic())
            elif time.monotonic() - last_progress[1] > args.timeout:
                raise DriveError(
                    f"time stood still for {args.timeout:g} s (did {args.node} stop?)"
                )
            if t < times[k]:
                continue
            seen.append({"t": t / 1e9, "input": self.input, "output": self.output})
            if k < len(levels):
                self.pub.publish(self._Float64(data=float(levels[k])))
            k += 1
        return seen, "simulated" if use_sim else "wall"


def _recorded_path(message: str) -> str:
    return message.split("recording to ", 1)[-1] if "recording to " in message else message


if __name__ == "__main__":
    sys.exit(main())
