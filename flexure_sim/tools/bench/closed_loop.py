"""
The closed loop, measured.

stage_node in real-time mode (recording on) with ``pi_controller`` in a second process answering
every measurement, at 1 kHz or, with ``--rate``, faster with the engine step scaled so that a
tick still takes `STEPS_PER_TICK` steps (what a slower machine does at 1 kHz).

    python -m flexure_sim.tools.bench.closed_loop --duration 10 [--rate 2000] [--monitor-rate 100]
        [--merge-late-ticks 2] [--param NAME=VALUE ...] [--hog] [--json]

The stage is the built-in one with a sensor (`SENSOR`: its noise makes every reading unique,
which is how commands are matched to the ticks they answer). Figures: the node's missed
ticks and tick jitter (its diagnostics, `measure.run_node`), and the command-to-applied
latency from the recording and the controller's trace (``trace_path``): each command (a
trace line) answers the reading it lists, published at the end of tick k (log time t_k), and
is found in the recording by its value, as the reading is (a value seen twice matches
nothing: counted unmatched); the node records each command with the log time of the tick
start that applied it, which for the very next tick k + 1 is t_k. So ``late = (log time of
the command - t_k) / T`` is 0 when the command was applied at the first tick after its
measurement (latency at most 1 tick) and n when it waited n more ticks. Matching by value, not
by order, a command lost before the node took it (one sent before its subscription matched)
shifts no other.

``--hog`` runs a CPU-bound process at niceness 19 next to them for the whole run (`Hog`): the
machine is then never idle, as a developer's desktop with a build or a browser running.
"""
from __future__ import annotations

import argparse
import json
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Optional, Sequence

import yaml

from flexure_sim import topics
from flexure_sim.engine.mechanism.loader import resolve_mechanism_path

#: The sensor of the measured stage (a capacitive gauge of 1 nm RMS noise).
SENSOR = {"noise_rms": 1.0e-9, "latency": 0, "seed": 1}
#: Setpoint of the run, m of output (the stage's output for ~0.7 um of drive).
SETPOINT = 2.0e-5
RATE = 1000.0
#: How long the controller may take to start, s.
START_TIMEOUT_S = 60.0
#: How long the controller may take to end after SIGINT, s (then it is killed).
STOP_TIMEOUT_S = 30.0
#: Engine steps per tick at every rate (the node's default at 1 kHz).
STEPS_PER_TICK = 10
#: A CPU-bound process at the lowest priority: it only takes time nobody else wants.
HOG = "import os\nos.nice(19)\nwhile True:\n    pass\n"


class Hog:
    """`HOG` in a subprocess until `stop`."""

    def __init__(self) -> None:
        self.proc = subprocess.Popen([sys.executable, "-c", HOG], stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def stop(self) -> None:
        self.proc.kill()
        self.proc.wait(30)


class ControllerProcess:
    """``pi_controller`` as a subprocess next to the node, tracing every command."""

    def __init__(self, env: dict[str, str], workdir: Path, period: float) -> None:
        self.trace = workdir / "controller_trace.txt"
        args = [sys.executable, "-m", "flexure_sim.node.apps.pi_controller", "--ros-args",
                "-p", f"setpoint:={SETPOINT!r}", "-p", f"period:={period!r}",
                "-p", f"measurement_topic:={topics.MEASURED}", "-p", f"trace_path:={self.trace}"]
        self._log = open(workdir / "controller.stderr", "wb")  # noqa: SIM115
        self.proc = subprocess.Popen(args, cwd=workdir, env=env, stdout=self._log,
                                     stderr=subprocess.STDOUT)
        # Started once its node exists (it opens the trace then): the warm-up follows.
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self.trace.exists():
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise RuntimeError("pi_controller did not start: "
                                   + (workdir / "controller.stderr").read_text()[-2000:])
            time.sleep(0.05)

    def stop(self) -> None:
        """SIGINT; a controller still running `STOP_TIMEOUT_S` later is killed, and that raised."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(STOP_TIMEOUT_S)
            raise RuntimeError(f"pi_controller did not end within {STOP_TIMEOUT_S:g} s of SIGINT: "
                               "killed") from None
        finally:
            self._log.close()


def sensor_stage(path: Path) -> Path:
    """Write the built-in stage with `SENSOR` to ``path`` and return the path."""
    data = yaml.safe_load(resolve_mechanism_path("microstage").read_text())
    data["sensor"] = dict(SENSOR)
    path.write_text(yaml.safe_dump(data))
    return path


def command_latency(recording: Path, trace: Path, period: float) -> dict[str, Any]:
    """`late` (module docstring) of every traced command the recording holds, summarised."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    readings: dict[float, int] = {}
    commands: dict[float, int] = {}
    repeated: set[float] = set()
    recorded = 0
    with open(recording, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(
                topics=["/" + topics.MEASURED, "/" + topics.COMMAND], log_time_order=False):
            is_command = channel.topic == "/" + topics.COMMAND
            seen = commands if is_command else readings
            recorded += is_command
            if decoded.data in seen:
                repeated.add(decoded.data)
            else:
                seen[decoded.data] = message.log_time
    period_ns = period * 1e9
    late: list[int] = []
    unmatched = 0
    lines = trace.read_text().splitlines()
    for line in lines:
        y, u = (float(v) for v in line.split()[1:3])
        if u not in commands:          # never recorded (commands_traced - commands_recorded)
            continue
        if y not in readings or y in repeated or u in repeated:
            unmatched += 1             # recorded, but its reading cannot be told
            continue
        late.append(round((commands[u] - readings[y]) / period_ns))
    n = len(late)
    ordered = sorted(late)
    return {
        "commands_traced": len(lines), "commands_recorded": recorded,
        "commands_matched": n, "commands_unmatched": unmatched,
        "applied_next_tick_fraction": sum(1 for v in late if v == 0) / n if n else None,
        "late_ticks_mean": statistics.fmean(late) if n else None,
        "late_ticks_p99": ordered[min(n - 1, int(0.99 * n))] if n else None,
        "late_ticks_max": ordered[-1] if n else None,
        "late_ticks_min": ordered[0] if n else None,
    }


def run(duration: float = 10.0, params: Optional[dict[str, str]] = None,
        hog: bool = False, rate: float = RATE) -> dict[str, Any]:
    """
    One real-time closed-loop run of ``duration`` s (after the warm-up) at ``rate`` Hz.

    The node's figures (`measure.run_node`) plus `command_latency`; ``hog``: next to `Hog`.
    The engine step is 1 / (`STEPS_PER_TICK` rate); the controller's period 1 / rate.
    """
    from flexure_sim.tools.bench import measure  # needs ROS 2

    workdir = Path(tempfile.mkdtemp(prefix="stage_closed_loop_"))
    period = 1.0 / rate
    hogger = Hog() if hog else None
    try:
        stage = sensor_stage(workdir / "stage_with_sensor.yaml")
        controllers: list[ControllerProcess] = []

        def start(env: dict[str, str], cwd: Path) -> ControllerProcess:
            controllers.append(ControllerProcess(env, cwd, period))
            return controllers[-1]

        result = measure.run_node("realtime", duration, rate, period / STEPS_PER_TICK, True, False,
                                  mechanism=str(stage), keep_dir=workdir, params=params,
                                  companion=start)
        result.update(command_latency(workdir / "measure.mcap", controllers[0].trace, period))
        result.pop("workdir", None)
        result["hog"] = hog
        return result
    finally:
        if hogger is not None:
            hogger.stop()
        shutil.rmtree(workdir, ignore_errors=True)


def summary(r: dict[str, Any]) -> str:
    """One line of the figures."""
    def pct(v: Optional[float]) -> str:
        return "n/a" if v is None else f"{100 * v:.2f} %"
    return (f"closed loop at {r['publish_rate'] / 1e3:g} kHz (pi_controller in a 2nd process, "
            f"recording on): missed ticks "
            f"{pct(r.get('missed_fraction'))} ({r.get('merged_ticks') or 0} of them merged, "
            f"real-time factor {r['real_time_factor']:.3f}), "
            f"jitter p50/p99 {1e6 * r['jitter_p50_s']:.0f}/"
            f"{1e6 * r['jitter_p99_s']:.0f} us, commands applied at the next tick "
            f"{pct(r['applied_next_tick_fraction'])} (late ticks mean "
            f"{None if r['late_ticks_mean'] is None else round(r['late_ticks_mean'], 3)}"
            f", p99 {r['late_ticks_p99']}, max {r['late_ticks_max']}; "
            f"{r['commands_matched']} matched, {r['commands_unmatched']} unmatched)")


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m flexure_sim.tools.bench.closed_loop",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=10.0, help="measuring window, s")
    parser.add_argument("--rate", type=float, default=RATE,
                        help=f"publish_rate, Hz (default {RATE:g}); the engine step is scaled "
                             f"to {STEPS_PER_TICK} steps a tick")
    parser.add_argument("--monitor-rate", type=float, default=0.0,
                        help="the node's monitor_rate, Hz (0: every tick)")
    parser.add_argument("--merge-late-ticks", type=int, default=0,
                        help="the node's merge_late_ticks (0: every late tick runs)")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="a further node parameter (e.g. stepping_priority=50)")
    parser.add_argument("--hog", action="store_true",
                        help="run a CPU-bound process at niceness 19 next to them")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    params = {"monitor_rate": repr(args.monitor_rate),
              "merge_late_ticks": repr(args.merge_late_ticks)}
    for item in args.param:
        name, sep, value = item.partition("=")
        if not sep or not name:
            parser.error(f"--param {item!r}: expected NAME=VALUE")
        params[name] = value
    r = run(args.duration, params=params, hog=args.hog, rate=args.rate)
    print(json.dumps(r) if args.json else summary(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
