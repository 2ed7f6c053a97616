"""``stage_node``: the ROS 2 shell around the engine's constrained twistor simulation.

    ros2 run flexure_sim stage_node [--ros-args -p mechanism:=<name|file.yaml> -p time_mode:=fast ...]

The node holds no physics. A dedicated stepping thread owns the `Simulation` and the
recording: per publish tick it applies the drive commands received since the last tick
(validated by `drive_input.CommandFilter`), advances the engine by
round(1 / (publish_rate * sim_step)) steps, and publishes the state (`interface`), packing
each message to CDR once and publishing and recording the same bytes. Real-time mode paces
ticks with absolute deadlines of a steady clock (`pacing.Pacer`); fast mode runs flat out and
publishes /clock; lockstep mode runs one tick per ``~/step`` call and publishes /clock.

The stepping thread also reads the drive commands: the command subscription is polled once
per tick (`polled`), so commands never wake the executor. The executor (main thread) serves
only services and parameter changes, which hand work to the stepping thread and wait for it. Topics, parameters and services are documented in README.md, "## stage_node".
"""
from __future__ import annotations

import collections
import concurrent.futures
import datetime as _dt
import gc
import math
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Optional

import rclpy
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import InvalidHandle, ParameterException
from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from std_srvs.srv import SetBool, Trigger

from .. import __version__
from ..engine.config import ConfigError, load_mechanism, resolve_mechanism_path
from ..recording import RecordingError
from ..engine.solver import Simulation, SolverError
from . import interface as itf
from .engine_guard import EngineHold, StrokeProbe, snapshot_finite
from .drive_input import CommandFilter, CommandStatus, DriveLimits, WarningThrottle, parse_float64_cdr
from .pacing import Pacer, set_thread_nice
from .polled import PolledGroup, never_called, take_raw
from .params import ParamSpec, parameter_specs, steps_per_tick, validate
from .record_process import ProcessRecording, RecorderProcess
from .session import (METADATA_NAME, PARAMETER_CHANGE_NAME, claim_recording_path, node_token,
                      release_claim)

NODE_NAME = "stage_node"
#: Engine's relinearize_tol: None = its default, re-linearize only when the step's iteration
#: stops contracting (the answer does not depend on where the Jacobian was taken), which lets
#: Simulation.step(n) run all n steps in one compiled loop.
RELINEARIZE_TOL = None
#: Most commands taken from the reader per tick (more wait for the next tick).
COMMAND_TAKE_LIMIT = itf.COMMAND_DEPTH
#: Diagnostics rate (Hz of simulated time), or every tick if the publish rate is lower.
DIAGNOSTICS_RATE = 10.0
#: How long a service waits for the stepping thread.
REQUEST_TIMEOUT_S = 30.0
#: Longest the main loop waits before checking that the node still runs. Each executor
#: wake-up holds the GIL ~0.4 ms, so it is rare.
SPIN_TIMEOUT_S = 1.0
#: GIL switch interval: keeps the stepping thread's latency low while callbacks run.
SWITCH_INTERVAL_S = 0.0005

_TYPE_CODES = {
    float: ParameterType.PARAMETER_DOUBLE,
    bool: ParameterType.PARAMETER_BOOL,
    str: ParameterType.PARAMETER_STRING,
    int: ParameterType.PARAMETER_INTEGER,
}


class StartupError(RuntimeError):
    """The node cannot start (bad mechanism, invalid parameters, recording impossible)."""


class _Window:
    """Accumulators of one diagnostics window (wall-clock timings of the stepping thread)."""

    __slots__ = ("ticks", "step_sum", "step_max", "snap_sum", "pub_sum", "pub_max", "tick_max",
                 "wall0", "sim0", "missed0", "lin0", "steps0", "counters0", "engine_failures0")

    def __init__(self, wall0: float, sim0: float, missed0: int, lin0: int, steps0: int,
                 counters0: dict[str, int], engine_failures0: int = 0) -> None:
        self.ticks = 0
        self.step_sum = self.step_max = self.snap_sum = self.pub_sum = self.pub_max = 0.0
        self.tick_max = 0.0
        self.wall0, self.sim0, self.missed0, self.lin0, self.steps0 = wall0, sim0, missed0, lin0, steps0
        self.counters0 = counters0
        self.engine_failures0 = engine_failures0


class StageNode(Node):
    """The stage node. Construct after ``rclpy.init``; call `shutdown` before destroy_node."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._log = self.get_logger()
        self._coerce_integer_overrides()
        # ---- mechanism and parameters (validated before anything starts) ----
        self._declare(parameter_specs()[0])
        mechanism_arg = self.get_parameter("mechanism").value
        try:
            self.mechanism = load_mechanism(mechanism_arg)
            self.mechanism_path = resolve_mechanism_path(mechanism_arg).resolve()
        except ConfigError as exc:
            raise StartupError(str(exc)) from exc
        drive = self.mechanism.drive
        defaults = (drive.stroke[0], drive.stroke[1], drive.slew_rate) if drive else None
        self._specs = {s.name: s for s in parameter_specs(defaults)}
        try:
            for spec in list(self._specs.values())[1:]:
                self._declare(spec)
        except ParameterException as exc:
            raise StartupError(f"invalid parameter: {exc}") from exc
        values = self._values()
        self._probe = StrokeProbe(self.mechanism, float(values["sim_step"]))
        own = {"stroke_min": defaults[0], "stroke_max": defaults[1]} if defaults else {}
        problem = validate(values) or self._stroke_problem(values, {**values, **own})
        if problem:
            raise StartupError(f"invalid parameters: {problem}")
        self.time_mode: str = values["time_mode"]
        self._dt = float(values["sim_step"])
        self._rate = float(values["publish_rate"])
        self._n_steps, _ = steps_per_tick(self._rate, self._dt)
        try:
            self.interface = itf.StageInterface(self.mechanism, self.time_mode)
        except ValueError as exc:
            raise StartupError(str(exc)) from exc
        self.sim = Simulation(self.mechanism, dt=self._dt, relinearize_tol=RELINEARIZE_TOL)
        try:
            # Warm up (compiled kernels, first Jacobian) before the first paced tick.
            self.sim.step(1)
            self.sim.snapshot()
            self.sim.reset()
        except Exception as exc:  # noqa: BLE001 - the engine's own message, at start-up
            raise StartupError(f"the engine failed its first step: {type(exc).__name__}: {exc}") from exc
        self.filter: Optional[CommandFilter] = None
        if drive is not None:
            self.filter = CommandFilter(self._limits(values))
            if self.filter.applied != 0.0:
                self.sim.set_command(self.filter.applied)

        # ---- publishers, subscription, services ----
        qos = itf.stream_qos()
        self._tick_pubs = [self.create_publisher(t.msg_type, t.name, qos) for t in self.interface.tick_topics]
        self._tick_names = [p.topic_name for p in self._tick_pubs]
        self._diag_pub = self.create_publisher(self.interface.diagnostics.msg_type,
                                               self.interface.diagnostics.name, qos)
        # Recording channels: the tick topics in publishing order, diagnostics, commands.
        self._diag_channel = len(self._tick_pubs)
        self._command_channel = len(self._tick_pubs) + 1
        self._command_sub = None
        self._command_topic = ""
        if self.interface.command is not None:
            self._command_sub = self.create_subscription(
                self.interface.command.msg_type, self.interface.command.name, never_called,
                itf.command_qos(), raw=True, callback_group=PolledGroup())
            self._command_topic = self._command_sub.topic_name
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(SetBool, "~/record", self._on_record)
        self.create_service(Trigger, "~/step", self._on_step)

        # ---- stepping-thread state ----
        self._requests: collections.deque[tuple[Callable[[], Any], concurrent.futures.Future]] = \
            collections.deque()
        self._wake = threading.Event()
        self._stop = threading.Event()
        #: Done when the stepping thread has ended (main() spins until then).
        self.stopped = Future()
        self._failure: Optional[BaseException] = None
        self._throttle = WarningThrottle(1.0)
        self._hold = EngineHold()
        self._ticks = 0
        self._wake_spin = float(values["wake_spin"])
        self._nice_request = int(values["stepping_nice"])
        self._nice = 0
        self._pacer: Optional[Pacer] = (
            Pacer(1.0 / self._rate, spin_s=min(self._wake_spin, 1.0 / self._rate))
            if self.time_mode == "realtime" else None)
        self._diag_every = max(1, round(self._rate / DIAGNOSTICS_RATE))
        self._recording: Optional[ProcessRecording] = None
        self._recorder_process: Optional[RecorderProcess] = None
        self._recording_index = 0
        self._recording_error = ""
        self._recorded_files: list[str] = []
        self._runs = 0
        self._window = self._new_window()
        self._run_wall0 = time.perf_counter()
        self._run_sim0 = self.sim.state.t
        if values["record"]:
            try:
                self._start_recording()
            except RecordingError as exc:
                if self._recorder_process is not None:
                    self._recorder_process.quit()
                raise StartupError(f"cannot record: {exc}") from exc
        self._sync_record_param = False
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        self._log.info(
            f"mechanism {self.mechanism.name} ({self.mechanism_path}), {self.time_mode} mode, "
            f"{self._rate:g} Hz x {self._n_steps} engine steps of {self._dt:g} s, "
            f"{len(self._tick_pubs)} topics per tick, recording "
            f"{self._recording.path if self._recording else 'off'}")
        # Everything built so far lives as long as the node: keep it out of the collector's
        # full passes, which would otherwise pause the stepping loop for milliseconds.
        gc.collect()
        gc.freeze()
        self._thread = threading.Thread(target=self._run, name="stage-stepping", daemon=True)
        self._thread.start()

    # ================================================================ parameters
    def _coerce_integer_overrides(self) -> None:
        """Accept ``-p publish_rate:=500`` for double parameters (ROS would reject the int)."""
        overrides = getattr(self, "_parameter_overrides", None)
        if not isinstance(overrides, dict):
            return
        for spec in parameter_specs():
            p = overrides.get(spec.name)
            if spec.type is float and p is not None and p.type_ == Parameter.Type.INTEGER:
                overrides[spec.name] = Parameter(spec.name, Parameter.Type.DOUBLE, float(p.value))

    def _declare(self, spec: ParamSpec) -> None:
        descriptor = ParameterDescriptor(
            name=spec.name,
            type=_TYPE_CODES[spec.type],
            description=spec.description + (f" [{spec.unit}]" if spec.unit else ""),
            read_only=spec.read_only,
        )
        if spec.type is float and spec.low is not None and spec.high is not None:
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(spec.low), to_value=float(spec.high), step=0.0)]
        if spec.type is int and spec.low is not None and spec.high is not None:
            descriptor.integer_range = [IntegerRange(from_value=int(spec.low), to_value=int(spec.high), step=1)]
        constraints = []
        if spec.name == "time_mode":
            constraints.append(f"one of {', '.join(itf.TIME_MODES)}")
        if spec.name == "sim_step":
            constraints.append("> 0 and divides 1/publish_rate")
        if spec.name == "slew_rate":
            constraints.append("> 0")
        if spec.name in ("stroke_min", "stroke_max"):
            constraints.append("stroke_min <= stroke_max")
        descriptor.additional_constraints = "; ".join(constraints)
        self.declare_parameter(spec.name, spec.default, descriptor)

    def _values(self) -> dict[str, Any]:
        return {name: self.get_parameter(name).value for name in self._specs}

    def _limits(self, values: dict[str, Any]) -> DriveLimits:
        return DriveLimits(float(values["stroke_min"]), float(values["stroke_max"]),
                           float(values["slew_rate"]))

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """On-set callback: check the whole resulting set of values; no side effects."""
        current = self._values()
        values = dict(current)
        for p in params:
            if p.name in values:
                values[p.name] = p.value
        problem = validate(values) or self._stroke_problem(values, current)
        return SetParametersResult(successful=problem is None, reason=problem or "")

    def _stroke_problem(self, values: dict[str, Any], current: dict[str, Any]) -> Optional[str]:
        """Why the engine could not follow the (changed) stroke ends in ``values``, or None."""
        if self.mechanism.drive is None:
            return None
        for name in ("stroke_max", "stroke_min"):
            if values[name] != current[name]:
                problem = self._probe.end_problem(name, values[name])
                if problem:
                    return problem
        return None

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """Post-set callback: hand accepted changes to the stepping thread."""
        names = {p.name for p in params}
        values = self._values()
        if names & {"stroke_min", "stroke_max", "slew_rate"} and self.filter is not None:
            limits = self._limits(values)
            self._call(lambda: self.filter.set_limits(limits))
        if names & {"publish_rate", "wake_spin"}:
            rate, spin = float(values["publish_rate"]), float(values["wake_spin"])
            self._call(lambda: self._set_pacing(rate, spin))
        if "record" in names and not self._sync_record_param:
            ok, message = self._set_recording(bool(values["record"]))
            (self._log.info if ok else self._log.error)(message)
        changed = {p.name: itf.value_text(p.value) for p in params}
        self._call(lambda: self._note_parameters(changed))

    def _note_parameters(self, changed: dict[str, str]) -> None:
        if self._recording is not None:
            self._recording.add_metadata(PARAMETER_CHANGE_NAME, {
                "t": repr(self.sim.state.t), **changed})

    def _set_pacing(self, rate: float, wake_spin: float) -> None:
        self._wake_spin = wake_spin
        if self._pacer is not None:
            self._pacer.spin_s = min(wake_spin, 1.0 / rate)
        if rate == self._rate:
            return
        self._rate = rate
        self._n_steps, _ = steps_per_tick(rate, self._dt)
        self._diag_every = max(1, round(rate / DIAGNOSTICS_RATE))
        if self._pacer is not None:
            self._pacer.set_period(1.0 / rate)
        self._log.info(f"publish_rate {rate:g} Hz: {self._n_steps} engine steps per tick")

    # ================================================================ callbacks
    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        ok, message = self._wait(self._call(self._reset))
        response.success, response.message = ok, message
        return response

    def _on_record(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        ok, message = self._set_recording(bool(request.data))
        if ok:
            self._sync_record_param = True
            try:
                self.set_parameters([Parameter("record", Parameter.Type.BOOL, bool(request.data))])
            finally:
                self._sync_record_param = False
        response.success, response.message = ok, message
        return response

    def _on_step(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self.time_mode != "lockstep":
            response.success = False
            response.message = f"~/step works in lockstep mode only (time_mode is {self.time_mode})"
            return response
        ok, message = self._wait(self._call(self._step_once))
        response.success, response.message = ok, message
        return response

    def _set_recording(self, on: bool) -> tuple[bool, str]:
        def change() -> tuple[bool, str]:
            if on:
                if self._recording is not None:
                    return True, f"already recording to {self._recording.path}"
                self._start_recording()
                return True, f"recording to {self._recording.path}"
            if self._recording is None:
                return True, "not recording"
            path = self._stop_recording()
            return True, f"closed {path}"
        return self._wait(self._call(change))

    # ============================================ hand-over to the stepping thread
    def _call(self, fn: Callable[[], Any]) -> concurrent.futures.Future:
        """Run ``fn`` in the stepping thread between ticks; the future holds its result."""
        future: concurrent.futures.Future = concurrent.futures.Future()
        if not self._thread_alive():
            # Before the thread starts (or after it stopped) nothing else touches the state.
            _run_into(fn, future)
            return future
        self._requests.append((fn, future))
        self._wake.set()
        return future

    def _thread_alive(self) -> bool:
        thread = getattr(self, "_thread", None)
        return thread is not None and thread.is_alive()

    @staticmethod
    def _wait(future: concurrent.futures.Future) -> tuple[bool, str]:
        try:
            result = future.result(timeout=REQUEST_TIMEOUT_S)
        except concurrent.futures.TimeoutError:
            return False, f"the stepping thread did not answer within {REQUEST_TIMEOUT_S:g} s"
        except (RecordingError, SolverError, OSError, ValueError) as exc:
            return False, str(exc)
        except Exception as exc:  # noqa: BLE001 - reported to the caller, the node stays up
            return False, f"{type(exc).__name__}: {exc}"
        if isinstance(result, tuple):
            return result
        return True, str(result) if result is not None else ""

    def _serve_requests(self) -> bool:
        """Run queued requests (stepping thread). Returns True if any ran."""
        ran = False
        while self._requests:
            fn, future = self._requests.popleft()
            _run_into(fn, future)
            ran = True
        return ran

    # ================================================================ stepping
    def _run(self) -> None:
        try:
            self._nice, refused = set_thread_nice(self._nice_request)
            if refused:
                self._log.info(f"stepping thread: {refused}")
            if self._pacer is not None:
                self._pacer.start()
            self._window = self._new_window()
            self._run_wall0, self._run_sim0 = time.perf_counter(), self.sim.state.t
            while not self._stop.is_set():
                if self._requests and self._serve_requests() and self._pacer is not None:
                    self._pacer.reanchor()
                if self.time_mode == "lockstep":
                    self._wake.wait(0.1)
                    self._wake.clear()
                    continue
                if self._pacer is not None:
                    self._pacer.wait()
                self._tick()
                if self._pacer is not None:
                    self._pacer.done()
        except BaseException as exc:  # noqa: BLE001 - reported, then the node shuts down
            if self._stop.is_set() or not self.context.ok():
                return  # shutting down: publishers may already be gone
            self._failure = exc
            try:
                self._log.fatal(f"simulation stopped: {type(exc).__name__}: {exc}")
            finally:
                self.context.try_shutdown()  # main()'s spin loop also watches `stepping`
        finally:
            # Fail whatever is still waiting.
            while self._requests:
                _, future = self._requests.popleft()
                if not future.done():
                    future.set_exception(RuntimeError("the node is shutting down"))
            try:
                self.stopped.set_result(self._failure is None)  # wakes the executor
            except (InvalidHandle, RuntimeError):
                pass  # the executor is already gone (shutdown): nobody to wake

    def _step_once(self) -> tuple[bool, str]:
        ok = self._tick()
        if not ok:
            return False, f"{self._hold.last_error}; state held at t = {self.sim.state.t:.9g} s"
        return True, f"t = {self.sim.state.t:.9g} s"

    def _advance_engine(self) -> None:
        """The tick's engine steps, following the drive filter's ramp."""
        sim = self.sim
        filt = self.filter
        if filt is not None:
            if filt.begin_tick(self._n_steps * self._dt):
                self._warn("rate_limited", "drive command faster than the slew limit "
                           f"({filt.limits.slew_rate:g} m/s): ramping")
            if filt.settled:
                if sim.state.command != filt.applied:
                    sim.set_command(filt.applied)
                sim.step(self._n_steps)
            else:
                dt = self._dt
                for _ in range(self._n_steps):
                    sim.set_command(filt.advance(dt))
                    sim.step(1)
        else:
            sim.step(self._n_steps)

    def _tick(self) -> bool:
        """One publish tick: commands, engine steps, publish + record every topic. Returns
        False when the engine failed: the state is then held (`EngineHold`) and nothing but
        the diagnostics is published."""
        perf = time.perf_counter
        t0 = perf()
        sim = self.sim
        if self._command_sub is not None:
            self._apply_commands(round(sim.state.t * 1e9))
        self._hold.save(sim, self.filter)
        try:
            self._advance_engine()
            t1 = perf()
            snap = sim.snapshot()
            if not snapshot_finite(snap):
                raise SolverError(f"non-finite result at t = {snap.t:.9g} s")
        except Exception as exc:  # noqa: BLE001 - any engine failure: hold, report, go on
            message = self._hold.restore(sim, self.filter, exc)
            count = self._throttle.event("engine")
            if count is not None:
                self._log.error(message + f" ({self._hold.failures} engine failures in all)")
            self._ticks += 1
            if self._ticks % self._diag_every == 0:
                self._publish_diagnostics(round(sim.state.t * 1e9))
            return False
        t2 = perf()
        stamp = round(snap.t * 1e9)
        payloads = self.interface.encode(snap, stamp)
        recording = self._recording
        if recording is not None:
            # Recorded first, so that the file holds every message a subscriber can have seen
            # even if a shutdown interrupts the publishing. Channels 0..n-1: the tick topics.
            try:
                recording.write_batch(list(enumerate(payloads)), stamp)
            except RecordingError as exc:
                self._recording_failed(exc)
        for pub, payload in zip(self._tick_pubs, payloads):
            pub.publish(payload)
        self._ticks += 1
        t3 = perf()
        w = self._window
        w.ticks += 1
        step_time, pub_time = t1 - t0, t3 - t2
        w.step_sum += step_time
        w.snap_sum += t2 - t1
        w.pub_sum += pub_time
        if step_time > w.step_max:
            w.step_max = step_time
        if pub_time > w.pub_max:
            w.pub_max = pub_time
        tick_time = t3 - t0
        if tick_time > w.tick_max:
            w.tick_max = tick_time
        if self._ticks % self._diag_every == 0:
            self._publish_diagnostics(stamp)
        return True

    def _apply_commands(self, stamp: int) -> None:
        """Take the commands received since the last tick; validate them in order; record each."""
        commands = take_raw(self._command_sub, COMMAND_TAKE_LIMIT)
        if not commands:
            return
        filt = self.filter
        received: list[tuple[int, bytes]] = []
        channel = self._command_channel
        for data in commands:
            received.append((channel, data))
            try:
                value = parse_float64_cdr(data)
            except ValueError:
                value = math.nan
            if filt is None:
                continue
            status = filt.submit(value)
            if status is CommandStatus.REJECTED:
                self._warn("rejected", f"drive command {value!r} rejected (not finite)")
            elif status is CommandStatus.CLAMPED:
                lim = filt.limits
                self._warn("clamped", f"drive command {value:g} m outside the stroke "
                           f"[{lim.stroke_min:g}, {lim.stroke_max:g}] m: clamped")

        recording = self._recording
        if recording is not None and received:
            try:
                recording.write_batch(received, stamp)
            except RecordingError as exc:
                self._recording_failed(exc)

    def _warn(self, kind: str, message: str) -> None:
        count = self._throttle.event(kind)
        if count is not None:
            total = getattr(self.filter.counters, kind) if self.filter else count
            suffix = f" ({count} such commands since the last warning, {total} in all)" if count > 1 else \
                f" ({total} in all)"
            self._log.warning(message + suffix)

    # ================================================================ recording
    def _start_recording(self) -> None:
        values = self._values()
        try:
            path = claim_recording_path(values["record_dir"], values["record_path"],
                                        self.mechanism.name, self._recording_index,
                                        node=node_token(self.get_fully_qualified_name()))
        except OSError as exc:
            raise RecordingError(f"cannot create a recording: {exc}") from exc
        qos = itf.stream_qos()
        topics = [(name, spec.type_name, qos)
                  for name, spec in zip(self._tick_names, self.interface.tick_topics)]
        topics.append((self._diag_pub.topic_name, self.interface.diagnostics.type_name, qos))
        if self._command_sub is not None:
            topics.append((self._command_topic, self.interface.command.type_name, itf.command_qos()))
        if self._recorder_process is None or not self._recorder_process.alive():
            self._recorder_process = RecorderProcess()
        try:
            self._recording = ProcessRecording(self._recorder_process, path, topics,
                                               self._metadata(values), METADATA_NAME, claimed=True)
        except BaseException:
            release_claim(path)
            raise
        self._recording_index += 1
        self._recording_error = ""
        self._recorded_files.append(str(path))
        self._log.info(f"recording to {path}")

    def _stop_recording(self) -> Optional[Path]:
        recording, self._recording = self._recording, None
        if recording is None:
            return None
        try:
            stats = recording.close()
        except RecordingError as exc:
            self._recording_error = str(exc)
            self._log.error(f"recording {recording.path} could not be finished: {exc}")
            return recording.path
        dropped = stats.get("dropped", 0) + recording.dropped_count
        self._log.info(f"closed {recording.path}: {stats.get('accepted', 0)} messages"
                       + (f", {dropped} dropped" if dropped else ""))
        return recording.path

    def _recording_failed(self, exc: BaseException) -> None:
        self._recording_error = str(exc)
        self._log.error(f"recording stopped: {exc}")
        recording, self._recording = self._recording, None
        if recording is not None:
            try:
                recording.close()
            except RecordingError:
                pass

    def _metadata(self, values: dict[str, Any]) -> dict[str, str]:
        mech = self.mechanism
        try:
            yaml_text = self.mechanism_path.read_text()
        except OSError:
            yaml_text = ""
        meta = {name: itf.value_text(value) for name, value in values.items()}
        meta.update({
            "mechanism_name": mech.name,
            "mechanism_path": str(self.mechanism_path),
            "mechanism_yaml": yaml_text,
            "node": self.get_fully_qualified_name(),
            "flexure_sim_version": __version__,
            "steps_per_tick": str(self._n_steps),
            "relinearize_tol": repr(RELINEARIZE_TOL),
            "root_frame": itf.ROOT_FRAME,
            "bodies": ",".join(self.interface.body_names),
            "hinges": ",".join(self.interface.hinge_names),
            "run": str(self._runs),
            "sim_time_start": repr(self.sim.state.t),
            "started_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        })
        return meta

    # ================================================================ reset
    def _reset(self) -> tuple[bool, str]:
        closed = self._stop_recording() if self._recording is not None else None
        was_recording = closed is not None
        self.sim.reset()
        if self.filter is not None:
            self.filter.reset()
            if self.filter.applied != 0.0:
                self.sim.set_command(self.filter.applied)
        if self._command_sub is not None:
            take_raw(self._command_sub, COMMAND_TAKE_LIMIT)  # sent before the reset: discarded
        self._runs += 1
        self._ticks = 0
        self._window = self._new_window()
        self._run_wall0, self._run_sim0 = time.perf_counter(), self.sim.state.t
        message = "simulation reset to t = 0"
        if closed is not None:
            message += f"; closed {closed}"
        if was_recording and self.get_parameter("record").value:
            self._start_recording()
            message += f"; recording to {self._recording.path}"
        self._log.info(message)
        return True, message

    # ================================================================ diagnostics
    def _counters(self) -> dict[str, int]:
        return self.filter.counters.as_dict() if self.filter else {}

    def _new_window(self) -> _Window:
        pacer = self._pacer
        return _Window(time.perf_counter(), self.sim.state.t, pacer.stats.missed if pacer else 0,
                       self.sim.stats.linearizations, self.sim.stats.steps, self._counters(),
                       self._hold.failures)

    def _publish_diagnostics(self, stamp: int) -> None:
        w = self._window
        now = time.perf_counter()
        t = self.sim.state.t
        wall = now - w.wall0
        rtf = (t - w.sim0) / wall if wall > 0 else 0.0
        n = max(w.ticks, 1)
        pacer = self._pacer
        counters = self._counters()
        new = {k: counters[k] - w.counters0.get(k, 0) for k in counters}
        stats = self.sim.stats
        steps = stats.steps - w.steps0
        level, notes = itf.OK, []
        missed_window = (pacer.stats.missed - w.missed0) if pacer else 0
        if missed_window:
            level, notes = itf.WARN, notes + [f"{missed_window} missed ticks"]
        if new.get("rejected"):
            level, notes = itf.WARN, notes + [f"{new['rejected']} commands rejected"]
        if new.get("clamped"):
            level, notes = itf.WARN, notes + [f"{new['clamped']} commands clamped"]
        if new.get("rate_limited"):
            notes.append(f"{new['rate_limited']} commands rate-limited")
        failures = self._hold.failures - w.engine_failures0
        if failures:
            level, notes = itf.ERROR, notes + [
                f"{failures} engine failures, state held: {self._hold.last_error}"]
        rec = self._recording
        if self._recording_error:
            level, notes = itf.ERROR, notes + [f"recording failed: {self._recording_error}"]
        elif rec is not None and rec.dropped_count:
            level, notes = itf.WARN, notes + [f"{rec.dropped_count} messages not recorded"]
        values: list[tuple[str, Any]] = [
            ("sim_time", t),
            ("time_mode", self.time_mode),
            ("real_time_factor", rtf),
            ("real_time_factor_run", (t - self._run_sim0) / max(now - self._run_wall0, 1e-9)),
            ("publish_rate", self._rate),
            ("sim_step", self._dt),
            ("steps_per_tick", self._n_steps),
            ("stepping_nice", self._nice),
            ("ticks", self._ticks),
            ("step_time_mean_us", 1e6 * w.step_sum / n),
            ("step_time_max_us", 1e6 * w.step_max),
            ("engine_step_time_mean_us", 1e6 * w.step_sum / max(steps, 1)),
            ("snapshot_time_mean_us", 1e6 * w.snap_sum / n),
            ("publish_time_mean_us", 1e6 * w.pub_sum / n),
            ("publish_time_max_us", 1e6 * w.pub_max),
            ("tick_time_mean_us", 1e6 * (w.step_sum + w.snap_sum + w.pub_sum) / n),
            ("tick_time_max_us", 1e6 * w.tick_max),
            ("solver_iterations", getattr(stats, "iterations", 0)),
            ("linearizations", stats.linearizations),
            ("linearizations_window", stats.linearizations - w.lin0),
            ("engine_steps", stats.steps),
            ("engine_failures", self._hold.failures),
            ("engine_error", self._hold.last_error),
        ]
        if pacer is not None:
            p50, p99 = pacer.stats.late_percentiles(0.5, 0.99)
            values += [
                ("missed_ticks", pacer.stats.missed),
                ("missed_ticks_window", missed_window),
                ("paced_ticks", pacer.stats.ticks),
                ("slips", pacer.stats.slips),
                ("skipped_ticks", pacer.stats.skipped),
                ("max_late_us", 1e6 * pacer.stats.max_late_s),
                ("wake_spin_us", 1e6 * pacer.spin_s),
                ("jitter_p50_us", 1e6 * p50),
                ("jitter_p99_us", 1e6 * p99),
            ]
        values += [(f"commands_{k}", v) for k, v in counters.items()]
        if self.filter is not None:
            values += [("drive_target", self.filter.target), ("drive_applied", self.filter.applied)]
        values += [
            ("recording", rec is not None),
            ("recording_path", str(rec.path) if rec is not None else ""),
            ("recorded_messages", rec.accepted_count if rec is not None else 0),
            ("recording_dropped", rec.dropped_count if rec is not None else 0),
        ]
        payload = itf.encode_diagnostics(
            stamp, f"{self.get_name()}: simulation", self.mechanism.name, level,
            "; ".join(notes) if notes else "running", values)
        if rec is not None:
            try:
                rec.write_batch(((self._diag_channel, payload),), stamp)
            except RecordingError as exc:
                self._recording_failed(exc)
        self._diag_pub.publish(payload)
        self._window = self._new_window()

    # ================================================================ shutdown
    def shutdown(self) -> None:
        """Stop the stepping thread and finish the recording (idempotent)."""
        self._stop.set()
        self._wake.set()
        if not self.context.ok():
            # rosout needs a valid context; log to the console only.
            self._log = rclpy.logging.get_logger(f"{self.get_logger().name}.shutdown")
        thread = getattr(self, "_thread", None)
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=REQUEST_TIMEOUT_S)
        if getattr(self, "_recording", None) is not None:
            self._stop_recording()
        process = getattr(self, "_recorder_process", None)
        if process is not None:
            process.quit()
            self._recorder_process = None

    @property
    def failure(self) -> Optional[BaseException]:
        return self._failure

    @property
    def stepping(self) -> bool:
        """True while the stepping thread runs."""
        return self._thread_alive()

    @property
    def recorded_files(self) -> list[str]:
        return list(self._recorded_files)


def _run_into(fn: Callable[[], Any], future: concurrent.futures.Future) -> None:
    if not future.set_running_or_notify_cancel():
        return
    try:
        future.set_result(fn())
    except BaseException as exc:  # noqa: BLE001 - handed to the waiting caller
        future.set_exception(exc)


USAGE = """usage: stage_node [--ros-args -p NAME:=VALUE ...]

Simulates a planar flexure mechanism (default: the built-in micropositioning stage) and
publishes its state; see README.md "## stage_node" for topics, frames and QoS.

parameters:
"""


def _usage() -> str:
    lines = [USAGE]
    for spec in parameter_specs((0.0, 2e-6, 0.01)):
        unit = f" [{spec.unit}]" if spec.unit else ""
        default = "mechanism's drive" if spec.name in ("stroke_min", "stroke_max", "slew_rate") else repr(spec.default)
        lines.append(f"  {spec.name}{unit} (default {default}{', read-only' if spec.read_only else ''}):")
        lines.append(f"      {spec.description}")
    lines.append("\nservices: ~/reset (std_srvs/Trigger), ~/record (std_srvs/SetBool), "
                 "~/step (std_srvs/Trigger, lockstep mode)")
    return "\n".join(lines)


def main(args: Optional[list[str]] = None) -> int:
    """Entry point of ``stage_node`` / ``ros2 run flexure_sim stage_node``."""
    argv = sys.argv if args is None else args
    user_args = rclpy.utilities.remove_ros_args(argv)[1:]
    if any(a in ("-h", "--help") for a in user_args):
        print(_usage())
        return 0
    if user_args:
        print(f"stage_node: error: unexpected arguments {user_args}; parameters go after "
              "--ros-args as -p NAME:=VALUE (see --help)", file=sys.stderr)
        return 2
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    # SIGINT raises KeyboardInterrupt; rclpy's handler turns SIGTERM into a context shutdown,
    # which ends spin_until_stopped. Either way `finally` then finishes the MCAP file.
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.ALL)
    node: Optional[StageNode] = None
    code = 0
    try:
        try:
            node = StageNode()
        except StartupError:
            raise
        except Exception:
            if rclpy.ok():
                raise
            return 0  # SIGINT/SIGTERM during start-up: nothing to finish
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        spin_until_stopped(executor, node.stopped, node.context)
    except KeyboardInterrupt:
        pass
    except StartupError as exc:
        print(f"stage_node: error: {exc}", file=sys.stderr)
        code = 1
    finally:
        _ignore_further_signals()
        if node is not None:
            node.shutdown()
            if node.failure is not None:
                code = 1
            node.destroy_node()
        rclpy.try_shutdown()
    return code


def spin_until_stopped(executor: Executor, stopped: Future, context: Context) -> None:
    """rclpy.spin, except that it also ends when `stopped` is done (the stepping thread ended).

    Only services, parameters and that end wake the executor, and a timeout once per
    SPIN_TIMEOUT_S: a safety net should a shutdown ever fail to wake it. A shutdown ends it
    wherever it lands. rclpy's signal thread (SIGTERM; SIGINT raises KeyboardInterrupt
    instead) shuts the context down concurrently with the executor, and when that lands
    while the executor builds its wait set, rclpy raises RCLError ("the given context is
    not valid") rather than ExternalShutdownException: the same shutdown, not a failure."""
    try:
        while context.ok() and not stopped.done():
            executor.spin_until_future_complete(stopped, timeout_sec=SPIN_TIMEOUT_S)
    except ExternalShutdownException:
        pass
    except _rclpy.RCLError:
        if context.ok():
            raise


def _ignore_further_signals() -> None:
    """While the recording is being finished, a second Ctrl-C must not cut it short."""
    if threading.current_thread() is not threading.main_thread():
        return
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(sig, signal.SIG_IGN)
        except (ValueError, OSError):
            pass


if __name__ == "__main__":
    sys.exit(main())
