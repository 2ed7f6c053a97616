"""
`StageNode`: the rclpy node around the engine, a thin shell.

It loads the mechanism, declares and validates the parameters (`params`, `declare`), creates
the publishers, the polled command subscription (`polled`, `commands`) and the services, and
hands everything that touches the simulation or the recording to the stepping thread
(`stepping`) through its request queue (`requests`). Recording files are managed by a
`session.RecordingSession`, diagnostics by `diagnostics`, incompatible QoS by `qos_watch`.
The executor (main thread) serves only services, parameter changes and QoS events. Topics,
parameters and services are documented in README.md, "## stage_node".
"""
from __future__ import annotations

import gc
from pathlib import Path
from typing import Any, Optional

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.context import Context
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from std_srvs.srv import SetBool, Trigger

from ..engine.config import ConfigError, load_mechanism, resolve_mechanism_path
from ..errors import FlexureSimError
from ..engine.solver import Simulation
from ..recording import RecordingError
from . import interface as itf
from .commands import CommandIntake
from .declare import coerce_integer_overrides, declare
from .diagnostics import Diagnostics
from . import display as dsp
from .display import Display, DisplayOutput, display_every, static_transforms, tf_message
from .display import tf_message_class
from .drive_input import CommandFilter, DriveLimits
from .engine_guard import StrokeProbe
from .params import as_declared_type, parameter_specs, validate
from .polled import PolledGroup, never_called
from .qos_watch import QosWatch
from .requests import REQUEST_TIMEOUT_S
from .session import PARAMETER_CHANGE_NAME, RecordingSession, run_metadata
from .stepping import RELINEARIZE_TOL, SteppingLoop

NODE_NAME = "stage_node"
#: Longest the main loop waits before checking that the node still runs. Each executor
#: wake-up holds the GIL ~0.4 ms, so it is rare.
SPIN_TIMEOUT_S = 1.0


class StartupError(FlexureSimError, RuntimeError):
    """The node cannot start (bad mechanism, invalid parameters, recording impossible)."""


def load(mechanism_arg: Any) -> tuple[Any, Path]:
    """
    Return the mechanism named by the ``mechanism`` parameter and its file.

    StartupError with the loader's one-line message (file: key: problem) if it does not load.
    """
    if not isinstance(mechanism_arg, str) or not mechanism_arg.strip():
        raise StartupError("parameter mechanism: expected a built-in name or a YAML path, got "
                           f"{mechanism_arg!r}")
    try:
        mech = load_mechanism(mechanism_arg)
        path = resolve_mechanism_path(mechanism_arg).resolve()
    except ConfigError as exc:
        raise StartupError(str(exc)) from exc
    except Exception as exc:  # noqa: BLE001 - whatever the loader lets through: one line
        raise StartupError(f"{mechanism_arg}: cannot load the mechanism "
                           f"({type(exc).__name__}: {exc})") from exc
    drives = mech.drives
    if len(drives) > 1 or any(d.kind != "displacement" for d in drives):
        kinds = ", ".join(f"{d.name} ({d.kind})" for d in drives)
        raise StartupError(f"{path}: mechanism {mech.name} has drives {kinds}: stage_node "
                           "steps one displacement drive (its statics: flexure-sim simulate "
                           "--static)")
    return mech, path


class StageNode(Node):
    """The stage node. Construct after ``rclpy.init``; call `shutdown` before destroy_node."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._log = self.get_logger()
        #: Done when the stepping thread has ended (main() spins until then).
        self.stopped = Future()
        self.loop: Optional[SteppingLoop] = None
        self.session = RecordingSession(self._log)
        try:
            self._build()
        except BaseException:
            self.shutdown()  # a recorder process may already run
            raise

    def _build(self) -> None:
        coerce_integer_overrides(self)
        # ---- mechanism and parameters (validated before anything starts) ----
        declare(self, parameter_specs()[0])
        self.mechanism, self.mechanism_path = load(self.get_parameter("mechanism").value)
        drive = self.mechanism.drive
        defaults = (drive.stroke[0], drive.stroke[1], drive.slew_rate) if drive else None
        self._specs = {s.name: s for s in parameter_specs(defaults)}
        try:
            for spec in list(self._specs.values())[1:]:
                declare(self, spec)
        except ParameterException as exc:
            raise StartupError(f"invalid parameter: {exc}") from exc
        values = self._values()
        self._probe = StrokeProbe(self.mechanism, float(values["sim_step"]))
        own = {"stroke_min": defaults[0], "stroke_max": defaults[1]} if defaults else {}
        problem = validate(values) or self._stroke_problem(values, {**values, **own})
        if problem:
            raise StartupError(f"invalid parameters: {problem}")
        time_mode = values["time_mode"]
        dt = float(values["sim_step"])
        try:
            self.interface = itf.StageInterface(
                self.mechanism, time_mode, values["frame_prefix"])
        except ValueError as exc:
            raise StartupError(str(exc)) from exc
        # No energy bookkeeping: the node publishes no energies (Model.energy).
        sim = Simulation(self.mechanism, dt=dt, relinearize_tol=RELINEARIZE_TOL, energy=False)
        try:
            # Warm up (compiled kernels, first Jacobian) before the first paced tick.
            sim.step(1)
            sim.snapshot()
            sim.reset()
        except Exception as exc:  # noqa: BLE001 - the engine's own message, at start-up
            raise StartupError(
                f"the engine failed its first step: {type(exc).__name__}: {exc}") from exc
        drive_filter: Optional[CommandFilter] = None
        if drive is not None:
            drive_filter = CommandFilter(self._limits(values))
            if drive_filter.applied != 0.0:
                sim.set_command(drive_filter.applied)

        # ---- publishers, subscription, services ----
        qos = itf.stream_qos()
        reliability = values["command_reliability"]
        self.qos_watch = watch = QosWatch(self._log, reliability)
        tick_pubs = [self.create_publisher(t.msg_type, t.name, qos,
                                           event_callbacks=watch.publisher_callbacks(t.name))
                     for t in self.interface.tick_topics]
        self._tick_names = [p.topic_name for p in tick_pubs]
        diag_pub = self.create_publisher(
            self.interface.diagnostics.msg_type, self.interface.diagnostics.name, qos,
            event_callbacks=watch.publisher_callbacks(self.interface.diagnostics.name))
        self._diag_topic = diag_pub.topic_name
        self.loop = loop = SteppingLoop(
            sim, drive_filter, self.interface, tick_pubs, self.session, self._log,
            time_mode=time_mode, rate=float(values["publish_rate"]), dt=dt,
            wake_spin=float(values["wake_spin"]), nice=int(values["stepping_nice"]),
            merge_after=int(values["merge_late_ticks"]),
            monitor_rate=float(values["monitor_rate"]))
        # Recording channels: the tick topics in publishing order, diagnostics, commands.
        self._command_sub = None
        if self.interface.command is not None:
            self._command_sub = self.create_subscription(
                self.interface.command.msg_type, self.interface.command.name, never_called,
                itf.command_qos(reliability), raw=True, callback_group=PolledGroup(),
            )
            command_topic = self._command_sub.topic_name
            self.create_timer(0.5, lambda: watch.check_command_publishers(self, command_topic),
                              callback_group=watch.group)
            loop.intake = CommandIntake(self._command_sub, drive_filter, len(tick_pubs) + 1,
                                        self.session.write, self._log, loop.throttle)
        loop.diagnostics = Diagnostics(loop, diag_pub, len(tick_pubs), self.get_name(),
                                       self.mechanism.name, watch.diagnostics)
        first = len(tick_pubs) + 1 + (self._command_sub is not None)  # after the command
        self._build_display(values, qos, watch, first)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(SetBool, "~/record", self._on_record)
        self.create_service(Trigger, "~/step", self._on_step)
        if values["record"]:
            try:
                self._start_recording()
            except RecordingError as exc:
                raise StartupError(f"cannot record: {exc}") from exc
        self._sync_record_param = False
        self.add_pre_set_parameters_callback(self._coerce_parameters)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        rec = self.session.current
        self._log.info(
            f"mechanism {self.mechanism.name} ({self.mechanism_path}), {time_mode} mode, "
            f"{loop.rate:g} Hz x {loop.n_steps} engine steps of {dt:g} s, "
            f"{len(tick_pubs)} topics per tick, recording {rec.path if rec else 'off'}")
        # Everything built so far lives as long as the node: keep it out of the collector's
        # full passes, which would otherwise pause the stepping loop for milliseconds.
        gc.collect()
        gc.freeze()
        loop.start(self._stepping_ended, self._stepping_failed)

    def _build_display(self, values: dict[str, Any], qos: Any, watch: QosWatch,
                       first_channel: int) -> None:
        """
        Markers publisher.

        TF publishers where tf2_msgs is importable, and the display output of the stepping thread
        (recording channels from ``first_channel`` on).
        """
        from visualization_msgs.msg import MarkerArray

        frames = self.interface.frames
        display = Display(self.mechanism, frames, float(values["display_scale"]))
        pub = self.create_publisher(MarkerArray, dsp.MARKERS.name, qos,
                                    event_callbacks=watch.publisher_callbacks(dsp.MARKERS.name))
        #: Extra recorded topics: (resolved name, type name, QoS), in channel order.
        self._display_topics = [(pub.topic_name, dsp.MARKERS.type_name, qos)]
        tf_class, why = tf_message_class()
        tf_pub = None
        if tf_class is None:
            self._log.info(f"TF off: {why}; poses are on bodies/poses and bodies/<body>/pose")
        else:
            tf_pub = self.create_publisher(tf_class, dsp.TF.name, dsp.tf_qos())
            static_pub = self.create_publisher(tf_class, dsp.TF_STATIC.name, dsp.tf_static_qos())
            static_pub.publish(tf_message(static_transforms(self.mechanism, frames),
                                          self.get_clock().now().nanoseconds, tf_class))
            self._tf_static_pub = static_pub
            self._display_topics += [(tf_pub.topic_name, dsp.TF.type_name, dsp.tf_qos()),
                                     (static_pub.topic_name, dsp.TF_STATIC.type_name,
                                      dsp.tf_static_qos())]
        channels = list(range(first_channel, first_channel + len(self._display_topics)))
        loop = self.loop
        loop.display = DisplayOutput(display, pub, self.session, channels, tf_pub, tf_class)
        loop.display_every = display_every(loop.rate, float(values["display_rate"]))

    @property
    def time_mode(self) -> str:
        return self.loop.time_mode

    # ================================================================ parameters
    def _values(self) -> dict[str, Any]:
        return {name: self.get_parameter(name).value for name in self._specs}

    @staticmethod
    def _limits(values: dict[str, Any]) -> DriveLimits:
        return DriveLimits(float(values["stroke_min"]), float(values["stroke_max"]),
                           float(values["slew_rate"]))

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

    def _coerce_parameters(self, params: list[Parameter]) -> list[Parameter]:
        """Pre-set callback: ``ros2 param set ... 1e-6`` or ``2`` sets a double parameter."""
        out = []
        for p in params:
            value = as_declared_type(self._specs.get(p.name), p.value)
            out.append(p if value is p.value else Parameter(p.name, Parameter.Type.DOUBLE, value))
        return out

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """On-set callback: check the whole resulting set of values; no side effects."""
        current = self._values()
        values = dict(current)
        for p in params:
            if p.name in values:
                values[p.name] = p.value
        problem = validate(values) or self._stroke_problem(values, current)
        return SetParametersResult(successful=problem is None, reason=problem or "")

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """Post-set callback: hand accepted changes to the stepping thread."""
        names = {p.name for p in params}
        values = self._values()
        loop = self.loop
        if names & {"stroke_min", "stroke_max", "slew_rate"} and loop.filter is not None:
            limits = self._limits(values)
            loop.requests.call(lambda: loop.filter.set_limits(limits))
        if names & {"publish_rate", "wake_spin", "monitor_rate", "merge_late_ticks"}:
            rate, spin = float(values["publish_rate"]), float(values["wake_spin"])
            monitor, merge = float(values["monitor_rate"]), int(values["merge_late_ticks"])
            loop.requests.call(lambda: loop.set_pacing(rate, spin, monitor, merge))
        if names & {"publish_rate", "display_rate"}:
            every = display_every(float(values["publish_rate"]), float(values["display_rate"]))
            loop.requests.call(lambda: setattr(loop, "display_every", every))
        if "display_scale" in names:
            scale = float(values["display_scale"])
            loop.requests.call(lambda: setattr(loop.display.display.scene, "display_scale", scale))
        if "record" in names and not self._sync_record_param:
            ok, message = self._set_recording(bool(values["record"]))
            (self._log.info if ok else self._log.error)(message)
        changed = {p.name: itf.value_text(p.value) for p in params}
        loop.requests.call(lambda: self.session.note(
            PARAMETER_CHANGE_NAME, {"t": repr(loop.sim.state.t), **changed}))

    # ================================================================ services
    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = self.loop.requests.run(self._reset)
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
            response.message = ("~/step works in lockstep mode only "
                                f"(time_mode is {self.time_mode})")
            return response
        response.success, response.message = self.loop.requests.run(self.loop.step_once)
        return response

    def _set_recording(self, on: bool) -> tuple[bool, str]:
        def change() -> tuple[bool, str]:
            current = self.session.current
            if on:
                if current is not None:
                    return True, f"already recording to {current.path}"
                return True, f"recording to {self._start_recording()}"
            if current is None:
                return True, "not recording"
            return True, f"closed {self.session.stop()}"
        return self.loop.requests.run(change)

    # ======================================================= stepping-thread work
    def _start_recording(self) -> Path:
        values = self._values()
        qos = itf.stream_qos()
        topics = [(name, spec.type_name, qos)
                  for name, spec in zip(self._tick_names, self.interface.tick_topics)]
        topics.append((self._diag_topic, self.interface.diagnostics.type_name, qos))
        if self._command_sub is not None:
            topics.append((self._command_sub.topic_name, self.interface.command.type_name,
                           itf.command_qos(values["command_reliability"])))
        topics += self._display_topics
        loop = self.loop
        node = self.get_fully_qualified_name()
        metadata = run_metadata(values, self.mechanism, self.mechanism_path, self.interface, node,
                                loop.n_steps, RELINEARIZE_TOL, loop.runs, loop.sim.state.t)
        return self.session.start(values, self.mechanism.name, node, topics, metadata,
                                  lossless=self.time_mode != "realtime")

    def _reset(self) -> tuple[bool, str]:
        closed = self.session.stop()
        self.loop.reset()
        message = "simulation reset to t = 0"
        if closed is not None:
            message += f"; closed {closed}"
            if self.get_parameter("record").value:
                message += f"; recording to {self._start_recording()}"
        self._log.info(message)
        return True, message

    # ================================================================ shutdown
    def _stepping_failed(self, exc: BaseException) -> bool:
        if not self.context.ok():
            return False  # shutting down: publishers may already be gone
        try:
            self._log.fatal(f"simulation stopped: {type(exc).__name__}: {exc}")
        finally:
            self.context.try_shutdown()  # ends main()'s spin loop
        return True

    def _stepping_ended(self, ok: bool) -> None:
        try:
            self.stopped.set_result(ok)  # wakes the executor
        except Exception:  # noqa: BLE001 - the executor is already gone: nobody to wake
            pass

    def shutdown(self) -> None:
        """Stop the stepping thread and finish the recording (idempotent)."""
        if not self.context.ok():
            # rosout needs a valid context; log to the console only.
            self._log = rclpy.logging.get_logger(f"{self.get_logger().name}.shutdown")
            self.session.log = self._log
        if self.loop is not None:
            self.loop.stop(REQUEST_TIMEOUT_S)
        self.session.close()

    @property
    def failure(self) -> Optional[BaseException]:
        return self.loop.failure if self.loop is not None else None


def spin_until_stopped(executor: Executor, stopped: Future, context: Context) -> None:
    """
    rclpy.spin, except that it also ends when `stopped` is done (the stepping thread ended).

    Only services, parameters and that end wake the executor, and a timeout once per
    SPIN_TIMEOUT_S: a safety net should a shutdown ever fail to wake it. A shutdown ends it
    wherever it lands. rclpy's signal handler shuts the context down concurrently with the
    executor, and when that lands while the executor builds its wait set, rclpy raises
    RCLError ("the given context is not valid") rather than ExternalShutdownException: the
    same shutdown, not a failure.
    """
    try:
        while context.ok() and not stopped.done():
            executor.spin_until_future_complete(stopped, timeout_sec=SPIN_TIMEOUT_S)
    except ExternalShutdownException:
        pass
    except _rclpy.RCLError:
        if context.ok():
            raise
