"""
Measure the stage node: real-time factor in fast mode and missed ticks in real-time mode.

    python -m flexure_sim.tools.bench.measure                      # both modes, 1 kHz, recording
    on python -m flexure_sim.tools.bench.measure --mode realtime --duration 30 --subscribe
    python -m flexure_sim.tools.bench.measure --profile            # where one tick's time goes (no
    DDS)

Starts ``stage_node`` as a subprocess (this interpreter, its own ROS domain on localhost, a
temporary working directory), listens to its ``/diagnostics`` with an rclpy node, and after a
warm-up compares the first and last diagnostics of the measuring window: real-time factor
(simulated / wall time), missed ticks per paced tick, mean engine / snapshot / publish times
per tick. ``--subscribe`` also subscribes to every published topic (DDS delivers every
message to a second process, as with a real consumer). The node is stopped with SIGINT and its
recording checked (complete, messages, bytes), then deleted unless ``--keep DIR``. ``--json``
prints one JSON object (a list for both modes).
"""
from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

from flexure_sim import topics
from flexure_sim.engine.solver.simulation import DEFAULT_STEP
from flexure_sim.node.publish.diagnostics import TICK_PARTS
from flexure_sim.tools.bench.tick_profile import profile


def _diag_values(msg: Any) -> dict[str, str]:
    return {kv.key: kv.value for kv in msg.status[0].values}


def _cpu_seconds(pid: int) -> Optional[float]:
    """CPU time (user + system, s) of a running process, from /proc (None without /proc)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_node(
    mode: str,
    duration: float,
    rate: float,
    sim_step: float,
    record: bool,
    subscribe: Sequence[str] | bool,
    warmup: float = 2.0,
    mechanism: str = "microstage",
    domain_id: Optional[int] = None,
    keep_dir: Optional[Path] = None,
    params: Optional[dict[str, str]] = None,
    flood_hz: float = 0.0,
    companion: Optional[Callable[[dict[str, str], Path], Any]] = None,
) -> dict[str, Any]:
    """
    Run the node in ``mode`` for warm-up + ``duration`` seconds and return the figures.

    ``params``: further node parameters (name -> value as on the command line). The node
    runs in ``keep_dir`` (kept) or in a temporary directory (removed afterwards).
    ``flood_hz``: during the measuring window another process (`flood`) publishes drive
    commands at that rate; the figures then include the commands received and the node's
    intake cost per command. ``companion(env, workdir)``: started once the node runs (before
    the warm-up), returns an object whose ``stop()`` ends it before the node stops.
    """
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile

    from flexure_sim.engine.mechanism.loader import load_mechanism
    from flexure_sim.node.publish.interface import StageInterface, value_text

    domain = domain_id if domain_id is not None else random.randint(1, 100)
    workdir = Path(keep_dir) if keep_dir else Path(tempfile.mkdtemp(prefix="stage_node_measure_"))
    workdir.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(workdir / "ros_log"), PYTHONUNBUFFERED="1")
    root = str(Path(__file__).resolve().parents[3])
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    node_params: dict[str, Any] = {
        "mechanism": mechanism,
        "time_mode": mode,
        "publish_rate": float(rate),
        "sim_step": float(sim_step),
        "record": record,
        "record_path": "measure.mcap",
        **(params or {}),
    }
    args = [sys.executable, "-m", "flexure_sim.node.stage.stage_node", "--ros-args"]
    for name, value in node_params.items():
        args += ["-p", f"{name}:={value_text(value)}"]
    stderr = open(workdir / "node.stderr", "wb")  # noqa: SIM115
    proc = subprocess.Popen(args, cwd=workdir, env=env, stdout=stderr, stderr=subprocess.STDOUT)

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("stage_node_measure", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    samples: list[tuple[float, dict[str, str]]] = []
    node.create_subscription(
        DiagnosticArray,
        "/diagnostics",
        lambda m: samples.append((time.monotonic(), _diag_values(m))),
        QoSProfile(depth=1000),
    )
    received = {"count": 0}
    if subscribe:
        itf = StageInterface(load_mechanism(mechanism), mode)

        def count(_: bytes) -> None:
            received["count"] += 1

        wanted = None if subscribe is True else {t.lstrip("/") for t in subscribe}
        for spec in itf.tick_topics:
            if wanted is None or spec.name.lstrip("/") in wanted:
                node.create_subscription(
                    spec.msg_type, spec.name, count, QoSProfile(depth=1000), raw=True
                )
    other = None
    try:
        deadline = time.monotonic() + 60.0
        while not samples:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"stage_node did not start: see {workdir / 'node.stderr'}")
            executor.spin_once(timeout_sec=0.1)
        if companion is not None:
            other = companion(env, workdir)
        start_at = time.monotonic() + warmup
        while time.monotonic() < start_at:
            executor.spin_once(timeout_sec=0.05)
        flooder = None
        if flood_hz > 0:  # flooding from the first to past the last sample of the window
            from flexure_sim.tools.bench.flood import FloodProcess

            flooder = FloodProcess(flood_hz, duration + 2.0, env)
            flooder.wait_started(lambda: executor.spin_once(timeout_sec=0.05))
        first = len(samples)
        received_start = received["count"]
        cpu_start, cpu_wall_start = _cpu_seconds(proc.pid), time.monotonic()
        end_at = time.monotonic() + duration
        while time.monotonic() < end_at:
            executor.spin_once(timeout_sec=0.05)
        window = samples[first - 1:]
        cpu_end, cpu_wall_end = _cpu_seconds(proc.pid), time.monotonic()
        flood = flooder.result() if flooder is not None else None
    finally:
        try:
            if other is not None:
                other.stop()  # may raise (a companion that would not stop): the node still stops
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
            try:
                proc.wait(60)
            finally:
                stderr.close()
                executor.shutdown(timeout_sec=1.0)
                node.destroy_node()
                rclpy.try_shutdown(context=context)
    if len(window) < 2:
        raise RuntimeError("fewer than two diagnostics in the measuring window")
    (w0, a), (w1, b) = window[0], window[-1]

    def delta(key: str) -> float:
        return float(b.get(key, 0)) - float(a.get(key, 0))

    def mean(key: str) -> float:
        return statistics.fmean(float(v[key]) for _, v in window[1:])

    sim = delta("sim_time")
    result: dict[str, Any] = {
        "mode": mode, "mechanism": mechanism, "publish_rate": rate, "sim_step": sim_step,
        "steps_per_tick": int(b["steps_per_tick"]), "record": record,
        "subscribed": ("all" if subscribe is True else ",".join(subscribe)) if subscribe else "",
        "params": dict(params or {}),
        "wall_s": w1 - w0, "sim_s": sim,
        "real_time_factor": sim / (w1 - w0),
        "ticks": int(delta("ticks")),
        # The parts of a tick (publish/diagnostics.py TICK_PARTS), means over the window.
        **{f"{part}_time_mean_us": mean(f"{part}_time_mean_us") for part in TICK_PARTS},
        "engine_step_time_mean_us": mean("engine_step_time_mean_us"),
        "tick_time_mean_us": mean("tick_time_mean_us"),
        "tick_time_max_us": max(float(v["tick_time_max_us"]) for _, v in window[1:]),
        "solver_iterations_per_step": delta("solver_iterations") / max(delta("engine_steps"), 1),
        "linearizations": int(delta("linearizations")),
        "topics_per_tick": None,
        # CPU time of the node process (all its threads, not the recorder) per wall second.
        "node_cpu_cores": ((cpu_end - cpu_start) / (cpu_wall_end - cpu_wall_start)
                           if cpu_start is not None and cpu_end is not None else None),
        # The stepping thread's niceness and SCHED_FIFO priority (0: none), the middleware
        # threads given that niceness, the PM QoS request held (-1: none); each None if the
        # node's diagnostics predate it.
        **{key: int(b[key]) if key in b else None
           for key in ("stepping_nice", "stepping_priority", "middleware_threads",
                       "cpu_latency_us")},
        "exit_code": proc.returncode,
    }
    if "missed_ticks" in b:
        paced = delta("paced_ticks")
        result.update(missed_ticks=int(delta("missed_ticks")), paced_ticks=int(paced),
                      missed_fraction=delta("missed_ticks") / paced if paced else None,
                      slips=int(delta("slips")), merged_ticks=int(delta("merged_ticks")),
                      max_late_us=float(b["max_late_us"]),
                      jitter_p50_s=1e-6 * float(b.get("jitter_p50_us", "nan")),
                      jitter_p99_s=1e-6 * float(b.get("jitter_p99_us", "nan")),
                      wake_spin_s=1e-6 * float(b.get("wake_spin_us", "nan")))
    if subscribe:
        result["messages_received_per_s"] = (received["count"] - received_start) / duration
    if flood is not None:
        # Intake cost per command: the windows' means weighted by their commands.
        counts = [float(v.get("commands_received", 0)) for _, v in window]
        per_window = [(n1 - n0, float(v.get("command_time_mean_us", 0.0)))
                      for n0, n1, (_, v) in zip(counts, counts[1:], window[1:])]
        taken = sum(n for n, _ in per_window)
        result.update(
            flood_hz=flood_hz, flood_sent_per_s=flood.get("sent_per_s"),
            flood_sent=flood.get("sent"), flood_all_acked=flood.get("all_acked"),
            commands_received=int(delta("commands_received")),
            commands_lost=int(delta("commands_lost")),
            command_time_mean_us=(sum(n * us for n, us in per_window) / taken
                                  if taken else None))
    if record:
        from flexure_sim.recording import log_info

        path = workdir / "measure.mcap"
        log = log_info(path, decode=False)  # ~1e6 messages: check the CRCs, decode none
        result.update(recording_complete=log.complete, recorded_messages=log.message_count,
                      recording_bytes=path.stat().st_size,
                      recording_dropped=int(log.dropped_messages or 0))
        # Per tick: every recorded topic but the command and its malformed payloads' channel,
        # diagnostics (~10 Hz) and the display topics (markers and TF at display_rate).
        not_per_tick = {"/diagnostics", "/drive/displacement", "/" + topics.MARKERS,
                        topics.TF, topics.TF_STATIC}
        result["topics_per_tick"] = sum(1 for t in log.topics
                                        if t not in not_per_tick and not t.endswith("/rejected"))
        if flood is not None:
            # The flood ended before the node was stopped: every command it sent must be in
            # the file (each received command is recorded, rejected ones included).
            command = log.topics.get("/" + topics.COMMAND)
            recorded = command.message_count if command is not None else 0
            result.update(flood_commands_recorded=recorded,
                          flood_commands_lost=int(flood.get("sent", 0)) - recorded)
    if keep_dir:
        result["workdir"] = str(workdir)
    else:
        shutil.rmtree(workdir, ignore_errors=True)
    return result


def _print_run(r: dict[str, Any]) -> None:
    print(
        f"== {r['mode']} mode: {r['mechanism']}, {r['publish_rate']:g} Hz x {r['steps_per_tick']} "
        "steps of "
        f"{r['sim_step']:g} s, recording {'on' if r['record'] else 'off'}"
        + (f", subscribed: {r['subscribed']}" if r["subscribed"] else "")
        + "".join(f", {k}:={v}" for k, v in r["params"].items())
    )
    print(f"   window {r['wall_s']:.1f} s wall, {r['sim_s']:.3f} s simulated, {r['ticks']} ticks")
    print(f"   real-time factor {r['real_time_factor']:.3f}")
    if r.get("paced_ticks"):
        print(
            f"   missed ticks {r['missed_ticks']} of {r['paced_ticks']} "
            f"({100 * r['missed_fraction']:.2f} %), "
            f"{r.get('merged_ticks', 0)} of them merged, "
            f"slips {r['slips']}, worst wake-up lateness {r['max_late_us']:.0f} us"
        )
    parts = ", ".join(f"{part} {r[f'{part}_time_mean_us']:.1f} us" for part in TICK_PARTS)
    print(f"   per tick: {parts}"
          + f"; in all {r['tick_time_mean_us']:.1f} us (max {r['tick_time_max_us']:.0f} us); "
          f"engine {r['engine_step_time_mean_us']:.2f} us/step, "
          f"{r['solver_iterations_per_step']:.2f} iterations/step")
    if r.get("node_cpu_cores") is not None:
        print(f"   node process CPU: {r['node_cpu_cores']:.2f} cores; stepping thread niceness "
              f"{r['stepping_nice']} (and {r.get('middleware_threads')} middleware threads), "
              f"SCHED_FIFO priority {r.get('stepping_priority')}, CPU "
              f"latency request {r.get('cpu_latency_us')} us")
    if r.get("flood_hz"):
        cost = r["command_time_mean_us"]
        print(f"   flood from another process: {r['flood_sent_per_s']:.0f} commands/s sent, "
              f"{r['commands_received']} received in the window; intake "
              + (f"{cost:.1f} us per command" if cost is not None else "n/a"))
        if "flood_commands_recorded" in r:
            print(f"   flood: {r['flood_sent']} commands sent in all, "
                  f"{r['flood_commands_recorded']} recorded, {r['flood_commands_lost']} not "
                  f"recorded; the node counted {r['commands_lost']} lost in the window "
                  f"(all acknowledged: {r.get('flood_all_acked')})")
    if r.get("messages_received_per_s") is not None:
        print(f"   subscriber received {r['messages_received_per_s']:.0f} messages/s")
    if r["record"]:
        print(
            f"   recording complete={r['recording_complete']}: {r['recorded_messages']} messages, "
            f"{r['recording_bytes'] / 1e6:.1f} MB, dropped {r['recording_dropped']}, "
            f"{r['topics_per_tick']} topics per tick"
        )


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m flexure_sim.tools.bench.measure",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--mode", choices=("fast", "realtime", "both"), default="both")
    parser.add_argument(
        "--duration", type=float, default=10.0, help="measuring window, s (default 10)"
    )
    parser.add_argument("--warmup", type=float, default=2.0, help="ignored start, s (default 2)")
    parser.add_argument(
        "--rate", type=float, default=1000.0, help="publish_rate, Hz (default 1000)"
    )
    parser.add_argument(
        "--sim-step",
        type=float,
        default=DEFAULT_STEP,
        help=f"sim_step, s (default {DEFAULT_STEP:g})",
    )
    parser.add_argument("--mechanism", default="microstage")
    parser.add_argument("--no-record", action="store_true", help="recording off (default on)")
    parser.add_argument("--subscribe", nargs="?", const="all", default="",
                        help="also subscribe (in this process) to every topic, or to a comma list "
                             "such as output/displacement,drive/force")
    parser.add_argument("--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="a further node parameter, e.g. wake_spin:=0.001 (repeatable)")
    parser.add_argument("--flood", type=float, default=0.0, metavar="HZ",
                        help="another process publishes drive commands at HZ during the window")
    parser.add_argument("--domain-id", type=int, default=None)
    parser.add_argument("--keep", type=Path, default=None, metavar="DIR",
                        help="run the node in DIR and keep its recording and logs there")
    parser.add_argument(
        "--profile", action="store_true", help="break one tick's cost down (no node)"
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    params: dict[str, str] = {}
    for item in args.param:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            parser.error(f"--param: expected NAME:=VALUE, got {item!r}")
        params[name] = value
    if args.profile:
        out = profile(args.rate, args.sim_step, mechanism=args.mechanism)
        if args.json:
            print(json.dumps(out))
        else:
            for key, value in out.items():
                print(f"{key:32s} {value:10.2f}")
        return 0
    modes = ("fast", "realtime") if args.mode == "both" else (args.mode,)
    results = []
    for mode in modes:
        subscribe: Sequence[str] | bool = (True if args.subscribe == "all"
                                           else [t for t in args.subscribe.split(",") if t])
        r = run_node(mode, args.duration, args.rate, args.sim_step, not args.no_record, subscribe,
                     warmup=args.warmup, mechanism=args.mechanism, domain_id=args.domain_id,
                     keep_dir=args.keep / mode if args.keep else None, params=params,
                     flood_hz=args.flood)
        results.append(r)
        if not args.json:
            _print_run(r)
    if args.json:
        print(json.dumps(results if len(results) > 1 else results[0]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
