"""
`StageNode`: the rclpy node around the engine, a thin shell.

It loads the mechanism, declares and validates the parameters (`params`, `declare`), creates
the publishers, the polled command subscription (`polled`, `commands`) and the services, and
hands everything that touches the simulation or the recording to the stepping thread
(`stepping`) through its request queue (`requests`); its services are in `services`.
Recording files are managed by a `session.RecordingSession`, diagnostics by `diagnostics`,
incompatible QoS by `qos_watch`.
The executor (main thread) serves only services, parameter changes and QoS events. Topics,
parameters and services are documented in docs/node.md.
"""
from __future__ import annotations

import gc
from pathlib import Path
from typing import Any, Callable, Optional

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import Bool
from std_srvs.srv import SetBool, Trigger

from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism, resolve_mechanism_path
from flexure_sim.engine.mechanism.spatial_loader import is_spatial, load_spatial
from flexure_sim.engine.mechanism.spatial_parts import Mechanism as SpatialMechanism
from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation
from flexure_sim.errors import FlexureSimError
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.recording import RecordingError
from flexure_sim.node.publish import interface as itf
from flexure_sim.node.publish.qos_profiles import READY_QOS, command_qos, stream_qos
from flexure_sim.node.publish.spatial_messages import SpatialInterface
from flexure_sim.node.stage.spatial_report import SpatialReport
from flexure_sim.node.inputs.command_intake import intake_for
from flexure_sim.node.params.declare import (
    coerce_integer_overrides, declare, undeclared_drive_overrides,
)
from flexure_sim.node.publish.diagnostics import DiagnosticsPort
from flexure_sim.node.publish import display as dsp
from flexure_sim.node.inputs.drive_bank import (
    FilterBank, command_limits, drive_limits, drive_parameter_specs, in_command_units,
    named_drives, units,
)
from flexure_sim.node.inputs.command_checks import CommandFilter, WarningThrottle
from flexure_sim.node.stage.engine_guard import StrokeProbe
from flexure_sim.node.stage.pacing import set_threads_nice
from flexure_sim.node.params.live import LiveParameters
from flexure_sim.node.stage.services import StageServices
from flexure_sim.node.params.table import SPACES, parameter_specs
from flexure_sim.node.stage.polled import PolledGroup, never_called
from flexure_sim.node.stage.qos_watch import QosWatch
from flexure_sim.node.stage.requests import REQUEST_TIMEOUT_S
from flexure_sim.node.record.session import RecordingSession
from flexure_sim.node.stage.loop_parts import LoopParts, LoopSettings
from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL, SteppingLoop

NODE_NAME = "stage_node"


#: How a parameter's expected type is named in start-up errors.
_TYPE_NAMES = {float: "double (a number)", int: "integer", bool: "bool (true or false)",
               str: "string"}


class StartupError(FlexureSimError, RuntimeError):
    """The node cannot start (bad mechanism, invalid parameters, recording impossible)."""


def load(mechanism_arg: Any, space: Any = "auto") -> tuple[Any, Path]:
    """
    Return the mechanism named by the ``mechanism`` parameter and its file.

    ``space`` (the parameter): ``auto`` loads a ``space: 3d`` file into the spatial engine and
    a planar file into the planar one, ``3d`` opens a planar file in space, ``2d`` refuses a
    3-D file. StartupError with the loader's one-line message (file: key: problem) if it does
    not load.
    """
    if not isinstance(mechanism_arg, str) or not mechanism_arg.strip():
        raise StartupError("parameter mechanism: expected a built-in name or a YAML path, got "
                           f"{mechanism_arg!r}")
    if space not in SPACES:
        raise StartupError(f"invalid parameters: space: expected one of {', '.join(SPACES)}, "
                           f"got {space!r}")
    try:
        spatial = space == "3d" or is_spatial(mechanism_arg)
        if spatial and space == "2d":
            raise StartupError(f"{mechanism_arg}: a 3-D mechanism (space: 3d) cannot run with "
                               "space 2d; use space auto or 3d")
        mech = load_spatial(mechanism_arg) if spatial else load_mechanism(mechanism_arg)
        path = resolve_mechanism_path(mechanism_arg).resolve()
    except StartupError:
        raise
    except ConfigError as exc:
        raise StartupError(str(exc)) from exc
    except Exception as exc:  # noqa: BLE001 - whatever the loader lets through: one line
        raise StartupError(f"{mechanism_arg}: cannot load the mechanism "
                           f"({type(exc).__name__}: {exc})") from exc
    return mech, path


class StageNode(LiveParameters, StageServices, Node):
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
        values = self._declare_parameters()
        self.interface = self._interface(values)
        sim, drive_filter = self._simulation(values)
        self.qos_watch = watch = QosWatch(self._log, values["command_reliability"])
        qos = stream_qos()
        tick_pubs = [self.create_publisher(
            t.msg_type, t.name, qos,
            event_callbacks=watch.publisher_callbacks(t.name, self._on_matched(k)))
            for k, t in enumerate(self.interface.tick_topics)]
        self._tick_names = [p.topic_name for p in tick_pubs]
        diagnostics = self.interface.diagnostics
        diag_pub = self.create_publisher(
            diagnostics.msg_type, diagnostics.name, qos,
            event_callbacks=watch.publisher_callbacks(diagnostics.name))
        self._diag_topic = diag_pub.topic_name
        # Recording channels: the tick topics in publishing order, diagnostics, commands, the
        # display's topics, the commands' malformed payloads (`_start_recording`).
        depth = values["command_depth"]
        self._command_subs = [self.create_subscription(
            spec.msg_type, spec.name, never_called,
            command_qos(values["command_reliability"], depth),
            raw=True, callback_group=PolledGroup()) for spec in self.interface.commands]
        command_topics = [sub.topic_name for sub in self._command_subs]
        display, self._display_topics, self._tf_static_pub = dsp.build_display(
            self, values, qos, watch, len(tick_pubs) + 1 + len(command_topics), self.spatial)
        throttle = WarningThrottle(1.0)
        drive = self._drive if not self._named else None
        intake = intake_for(self._command_subs, drive_filter, self._named, len(tick_pubs) + 1,
                            self.session.write, self._log, throttle,
                            units(drive)[0] if drive else "m",
                            len(tick_pubs) + 1 + len(command_topics) + len(self._display_topics),
                            depth)

        def check_graph() -> None:  # by the stepping thread, not on an executor timer
            for topic in command_topics:
                watch.check_command_publishers(self, topic)
        parts = LoopParts(
            LoopSettings.from_values(values), sim, self.interface, tick_pubs, self.session,
            self._log, filter=drive_filter, intake=intake, display=display, throttle=throttle,
            graph_check=check_graph if command_topics else None,
            report=SpatialReport(sim) if self.spatial else None,
            diagnostics=DiagnosticsPort(diag_pub, len(tick_pubs), self.get_name(),
                                        self.mechanism.name, watch.diagnostics))
        self.loop = loop = SteppingLoop(parts)
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
            f"mechanism {self.mechanism.name} ({self.mechanism_path})"
            f"{', spatial engine (3-D)' if self.spatial else ''}, {loop.time_mode} mode, "
            f"{loop.rate:g} Hz x {loop.n_steps} engine steps of {loop.dt:g} s, "
            f"{len(tick_pubs)} topics per tick, recording {rec.path if rec else 'off'}")
        # Everything built so far lives as long as the node: keep it out of the collector's
        # full passes, which would otherwise pause the stepping loop for milliseconds.
        gc.collect()
        gc.freeze()
        # Latched: a driver that subscribes later still gets it (docs/controller_guide.md).
        ready = self.create_publisher(Bool, "~/ready", READY_QOS)
        loop.start(self._stepping_ended, self._stepping_failed,
                   lambda: ready.publish(Bool(data=True)))

    def _on_matched(self, index: int) -> Callable[[Any], None]:
        """Return tick topic ``index``'s matched-event callback: published while subscribed."""
        def matched(status: Any) -> None:
            if self.loop is not None:
                self.loop.publish_calls.set_subscribed(index, int(status.current_count) > 0)
        return matched

    def _declare_parameters(self) -> dict[str, Any]:
        """
        Declare the parameters, load the mechanism; return the values, validated as a whole.

        StartupError names what is wrong.
        """
        coerce_integer_overrides(self)
        first = parameter_specs()[:2]  # mechanism and space: what to load
        for spec in first:
            self._declare_checked(spec)
        self.mechanism, self.mechanism_path = load(self.get_parameter("mechanism").value,
                                                   self.get_parameter("space").value)
        #: True: the spatial engine runs (a ``space: 3d`` file, or ``space:=3d``).
        self.spatial = isinstance(self.mechanism, SpatialMechanism)
        #: The first drive (a planar mechanism's ``drive``), None without one.
        self._drive = self.mechanism.drives[0] if self.mechanism.drives else None
        #: The named drives (several, or a force drive; `drive_bank`), else the single drive.
        self._named = named = named_drives(self.mechanism)
        drive = self._drive if not named else None
        defaults = command_limits(drive) if drive else None
        specs = parameter_specs(defaults, "each drive has its own drives.<name>.* limits"
                                if named else "the mechanism has no drive")
        self._specs = {s.name: s for s in (in_command_units(specs, drive) if drive else specs)
                       + drive_parameter_specs(named)}
        for spec in list(self._specs.values())[len(first):]:
            self._declare_checked(spec)
        unknown = undeclared_drive_overrides(self, [d.name for d in named], drive is not None)
        if unknown:
            raise StartupError(f"invalid parameter {unknown}")
        values = self._values()
        self._probe = StrokeProbe(self.mechanism, float(values["sim_step"]),
                                  SpatialSimulation if self.spatial else Simulation)
        own = {"stroke_min": defaults[0], "stroke_max": defaults[1]} if defaults else {}
        own.update({s.name: s.default for s in drive_parameter_specs(named)})
        problem = self._problem(values, {**values, **own})
        if problem:
            raise StartupError(f"invalid parameters: {problem}")
        return values

    def _declare_checked(self, spec: Any) -> None:
        """
        Declare one parameter; StartupError naming it if its override is refused.

        Refused for its type (the type expected and the one given) or, of the right type,
        for the parameter's range (the value and the range).
        """
        try:
            declare(self, spec)
        except ParameterException as exc:
            given = self._parameter_overrides.get(spec.name)
            if (given is not None and type(given.value) is spec.type
                    and spec.low is not None and spec.high is not None):
                raise StartupError(
                    f"invalid parameter {spec.name}: {given.value!r} is outside its range "
                    f"[{spec.low:g}, {spec.high:g}]{' ' + spec.unit if spec.unit else ''}"
                ) from exc
            got = (f"got {given.type_.name.lower()} {given.value!r}" if given is not None
                   else str(exc))
            raise StartupError(f"invalid parameter {spec.name}: expected a "
                               f"{_TYPE_NAMES[spec.type]}, {got}") from exc

    def _interface(self, values: dict[str, Any]) -> itf.StageInterface:
        kind = SpatialInterface if self.spatial else itf.StageInterface
        try:
            return kind(self.mechanism, values["time_mode"], values["frame_prefix"])
        except ValueError as exc:
            raise StartupError(str(exc)) from exc

    def _simulation(self, values: dict[str, Any]) -> tuple[Any, Any]:
        """Build the simulation, stepped once and reset (warm), and the drives' command filter."""
        self._log.info(f"building {self.mechanism.name} (the first start after an install "
                       "compiles the engine's kernels: up to a minute, then cached)")
        # No energy bookkeeping: the node publishes no energies (Model.energy; none in 3-D).
        sim: Any
        if self.spatial:
            sim = SpatialSimulation(self.mechanism, dt=float(values["sim_step"]),
                                    relinearize_tol=RELINEARIZE_TOL)
        else:
            sim = Simulation(self.mechanism, dt=float(values["sim_step"]),
                             relinearize_tol=RELINEARIZE_TOL, energy=False)
        try:
            # Warm up (compiled kernels, first Jacobian) before the first paced tick.
            sim.step(1)
            sim.snapshot()
            sim.reset()
        except Exception as exc:  # noqa: BLE001 - the engine's own message, at start-up
            raise StartupError(
                f"the engine failed its first step: {type(exc).__name__}: {exc}") from exc
        drive = self._drive if not self._named else None
        drive_filter: Any = None
        if drive is not None:
            drive_filter = CommandFilter(self._limits(values))
        elif self._named:
            drive_filter = FilterBank([d.name for d in self._named],
                                      [drive_limits(values, d.name) for d in self._named])
        if drive_filter is not None and drive_filter.differs(0.0):
            sim.set_command(drive_filter.applied)
        return sim, drive_filter

    @property
    def time_mode(self) -> str:
        return self.loop.time_mode

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

    def adopt_middleware_threads(self, tids: set[int]) -> None:
        """
        Give the middleware's threads ``tids`` the niceness asked for the stepping thread.

        The stepping thread takes and publishes through the middleware and waits on its locks.
        A middleware thread holding one at niceness 0 waits behind the other processes for the
        shared core while the stepping thread waits for it (a priority inversion): next to a
        controller that blocked a tick for 1.1-1.6 ms every one to three seconds
        (BENCHMARKS.md). Threads they start later inherit the niceness. ``tids``: the threads
        ROS started in this process (`stage_node` passes them; in-process nodes do not).
        """
        nice = self.loop.nice_request
        done, refused = set_threads_nice(tids, nice) if tids else (0, "")
        self.loop.middleware_threads = done
        if refused:
            self._log.info(f"middleware threads: {refused}; {len(tids) - done} of {len(tids)} "
                           "keep their niceness")

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
