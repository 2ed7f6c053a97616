"""
``pi_controller``: an example controller closing the loop around ``stage_node``.

    ros2 run flexure_sim pi_controller [--ros-args -p kp:=0.01 -p ki:=20.0 ...]

A thin rclpy shell around `flexure_sim.control.pi_notch.PIController`: it subscribes the
measurement (``output/measured``, or ``output/displacement``), keeps the latest setpoint
(``setpoint``, std_msgs/Float64, m of output; the ``setpoint`` parameter is its initial
value) and answers every measurement received with exactly one command on
``drive/displacement`` (std_msgs/Float64, m). Nothing is timed by a clock: one command per
measurement, so in the stage's lockstep mode the run is a deterministic function of the
measurements (docs/controller_guide.md). The measurement
subscription keeps only the newest reading (reliable, keep last 1): in real time a
controller that fell behind skips stale readings rather than answering them ever later.

Measurements and setpoints are taken and answered in the main thread (`answer_loop`), the
services and parameters by an executor thread beside it: an rclpy executor's wake-up costs
several times the answer itself, at 2 kHz more than half a core (figures in `answer_loop`).

A non-finite setpoint is refused (the setpoint stays), a non-finite measurement is answered
with the last command; both with a throttled WARN naming the topic and the value, the law's
state untouched (`PIController.update` refuses before changing it).

``handshake`` (lockstep drivers): after each command the node waits until every matched
reliable subscriber (the stage) has acknowledged it (`Publisher.wait_for_all_acked`), then
publishes the number of measurements answered so far on ``~/answered`` (std_msgs/UInt64). A
driver that calls the stage's ``~/step`` for tick k + 1 only after ``~/answered`` reached k
knows the command is in the stage's reader before the tick that applies it. (Merely seeing
the command arrive in the driver is not enough: DDS does not order deliveries to different
readers, and a race was observed.) Fast DDS acknowledges on the writer's heartbeat period,
3 s by default: run the controller with ``FASTRTPS_DEFAULT_PROFILES_FILE`` set to the
installed ``config/fastdds_fast_ack.xml`` (1 ms).

``~/reset`` (std_srvs/Trigger): integral and notch state to rest, answer count to 0, setpoint
to its parameter: call it with the stage's ``~/reset`` to start a new run.

``trace_path``: one line per measurement (index, measurement, command, wall time of the
publish in ns, `time.time_ns`) for the benchmark's command-to-applied latency.
"""
from __future__ import annotations

import math
import sys
import threading
import time
from contextlib import contextmanager
from typing import Any, Iterator, Optional

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.duration import Duration
from rclpy.exceptions import InvalidTopicNameException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64, UInt64
from std_srvs.srv import Trigger

from flexure_sim import topics
from flexure_sim.console import quiet_pipe
from flexure_sim.control.pi_notch import NonFiniteInput, PIConfig, PIController
from flexure_sim.errors import FlexureSimError
from flexure_sim.node.apps.answer_loop import AnswerLoop
from flexure_sim.node.release import release
from flexure_sim.node.stage.polled import PolledGroup

#: (name, default, description) of every parameter; all can be changed live except the
#: topics, ``handshake`` and ``trace_path`` (read-only). The default gains suit the built-in
#: stage at 1 kHz (loop crossover ~45 Hz; a 2 % settling time of ~6-13 ms without overshoot
#: for a sensor of up to 1 tick latency and 2 kHz bandwidth).
PARAMETERS: tuple[tuple[str, Any, str], ...] = (
    ("kp", 0.005, "proportional gain, m of command per m of error"),
    ("ki", 10.0, "integral gain, 1/s (command per error-second)"),
    ("period", 1e-3, "sample period T of the discrete law, s: the stage's 1/publish_rate"),
    ("notch_frequency", 0.0, "notch centre, Hz (0: no notch; the stage's first mode: "
                             "`flexure-sim modes`)"),
    ("notch_damping", 0.1, "notch damping ratio zeta (width: about 2 zeta f0), > 0"),
    ("notch_depth", 0.0, "gain of the notch at its centre, [0, 1] (0: full notch)"),
    ("command_min", 0.0, "lowest command, m (the stage's stroke_min)"),
    ("command_max", 2e-6, "highest command, m (the stage's stroke_max)"),
    ("setpoint", 0.0, "initial setpoint, m of output (the setpoint topic overrides it)"),
    ("measurement_topic", topics.MEASURED, "measurement subscribed (output/measured or "
                                           "output/displacement)"),
    ("setpoint_topic", topics.SETPOINT, "setpoint subscribed, m of output"),
    ("command_topic", topics.COMMAND, "command published, m of drive"),
    ("handshake", False, "lockstep: wait for the stage's acknowledgement of each command, "
                         "then publish the count on ~/answered"),
    ("trace_path", "", "file of one line per measurement: index, measurement, command, "
                       "publish wall time (ns); empty: none"),
)
READ_ONLY = {"measurement_topic", "setpoint_topic", "command_topic", "handshake", "trace_path"}
#: How long `handshake` waits for the acknowledgement of one command, s.
ACK_TIMEOUT = 10.0
#: At most one warning about refused (non-finite) inputs per topic in this many seconds.
WARN_PERIOD = 1.0


class StartupError(FlexureSimError, RuntimeError):
    """The controller cannot start (one line on stderr, exit code 1)."""


@contextmanager
def topic_parameter(name: str, values: dict[str, Any]) -> Iterator[None]:
    """Turn rclpy's InvalidTopicNameException into a StartupError naming the parameter."""
    try:
        yield
    except InvalidTopicNameException as exc:
        reason = str(exc).splitlines()[0].removeprefix("Invalid topic name: ").rstrip(":")
        raise StartupError(f"invalid parameter {name}: {values[name]!r} is not a valid "
                           f"topic name ({reason})") from exc


def parameter_problem(values: dict[str, Any]) -> str:
    """Why these parameter values cannot be used ("" if they can), naming the parameter."""
    for name in ("kp", "ki", "period", "command_min", "command_max", "notch_frequency",
                 "notch_damping", "notch_depth", "setpoint"):
        try:
            value = float(values[name])
        except (TypeError, ValueError):
            return f"{name} must be a number, got {values[name]!r}"
        if not math.isfinite(value):
            return f"{name} must be finite, got {value!r}"
    return config_from(values).problem()


def config_from(values: dict[str, Any]) -> PIConfig:
    """Return the law's configuration from parameter values (by name)."""
    return PIConfig(
        kp=float(values["kp"]), ki=float(values["ki"]), period=float(values["period"]),
        u_min=float(values["command_min"]), u_max=float(values["command_max"]),
        notch_frequency=float(values["notch_frequency"]),
        notch_damping=float(values["notch_damping"]), notch_depth=float(values["notch_depth"]))


#: The command topic's QoS and the measurement's: the newest reading only. A controller that
#: fell behind answers the latest reading instead of working through a queue of stale ones
#: (whose answers would come ever later); in lockstep nothing is skipped (one reading per step).
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                 reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
NEWEST = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


class PIControllerNode(Node):
    """The controller node (module docstring): one command per measurement received."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("pi_controller", **kwargs)
        for name, default, text in PARAMETERS:
            # Doubles accept integers too (-p ki:=20): the law converts with float().
            self.declare_parameter(name, default, ParameterDescriptor(
                description=text, read_only=name in READ_ONLY,
                dynamic_typing=isinstance(default, float)))
        values = self.values()
        problem = parameter_problem(values)
        if problem:
            raise StartupError(f"invalid parameters: {problem}")
        self.law = PIController(config_from(values))
        self.setpoint = float(values["setpoint"])
        self.command = self.law.rest_command()  # the last command published (held on refusal)
        self.answered = 0
        self.handshake = bool(values["handshake"])
        path = values["trace_path"]
        self.trace = open(path, "w") if path else None  # noqa: SIM115
        with topic_parameter("command_topic", values):
            self.command_pub = self.create_publisher(Float64, values["command_topic"], QOS)
        self.answered_pub = (self.create_publisher(UInt64, "~/answered", QOS)
                             if self.handshake else None)
        # Served by `answer_loop` in the main thread, one at a time (`lock` against the rest).
        polled = PolledGroup()
        with topic_parameter("measurement_topic", values):
            self.measurement_sub = self.create_subscription(
                Float64, values["measurement_topic"], self.on_measurement, NEWEST,
                callback_group=polled)
        with topic_parameter("setpoint_topic", values):
            self.setpoint_sub = self.create_subscription(
                Float64, values["setpoint_topic"], self.on_setpoint, QOS, callback_group=polled)
        self.lock = threading.Lock()
        self.create_service(Trigger, "~/reset", self.on_reset)
        self.add_on_set_parameters_callback(self.validate)
        self.add_post_set_parameters_callback(self.apply)
        c = self.law.config
        self.get_logger().info(
            f"PI kp {c.kp:g}, ki {c.ki:g} 1/s, T {c.period:g} s, notch "
            f"{c.notch_frequency:g} Hz, command [{c.u_min:g}, {c.u_max:g}] m; "
            f"{self.resolve_topic_name(values['measurement_topic'])} -> "
            f"{self.command_pub.topic_name}")

    def values(self) -> dict[str, Any]:
        return {name: self.get_parameter(name).value for name, _, _ in PARAMETERS}

    def validate(self, params: list[Any]) -> Any:
        values = {**self.values(), **{p.name: p.value for p in params}}
        problem = parameter_problem(values)
        return SetParametersResult(successful=not problem, reason=problem)

    def apply(self, params: list[Any]) -> None:
        with self.lock:
            self._apply(params)

    def _apply(self, params: list[Any]) -> None:
        values = self.values()
        law = PIController(config_from(values))
        law.integral = self.law.integral  # the integral carries over (no bump)
        self.law = law
        if any(p.name == "setpoint" for p in params):
            self.setpoint = float(values["setpoint"])

    def on_reset(self, _request: Any, response: Any) -> Any:
        """
        Integral and notch back to rest.

        Answer count to 0, setpoint to the parameter (with the stage's ~/reset: a new run).
        """
        with self.lock:
            return self._reset(response)

    def _reset(self, response: Any) -> Any:
        self.law.reset()
        self.command = self.law.rest_command()
        self.answered = 0
        self.setpoint = float(self.get_parameter("setpoint").value)
        response.success, response.message = True, "controller reset"
        return response

    def on_setpoint(self, msg: Any) -> None:
        value = float(msg.data)
        if not math.isfinite(value):
            # One call site per topic: rclpy throttles per call site.
            self.get_logger().warn(
                f"refused a non-finite value {value!r} on {self.setpoint_sub.topic_name}: "
                f"the setpoint stays {self.setpoint!r}", throttle_duration_sec=WARN_PERIOD)
            return
        self.setpoint = value

    def polled(self) -> list[tuple[Any, Any]]:
        """Return the subscriptions `answer_loop` serves, with their callbacks."""
        return [(self.measurement_sub, self.on_measurement), (self.setpoint_sub, self.on_setpoint)]

    def on_measurement(self, msg: Any) -> None:
        with self.lock:
            self._answer(msg)

    def _answer(self, msg: Any) -> None:
        y = float(msg.data)
        try:
            u = self.command = self.law.update(self.setpoint, y)
        except NonFiniteInput:
            # Still one answer per measurement (lockstep drivers count them): the last command,
            # the law's state untouched.
            u = self.command
            self.get_logger().warn(
                f"refused a non-finite value {y!r} on {self.measurement_sub.topic_name}: "
                f"the last command {u!r} is repeated", throttle_duration_sec=WARN_PERIOD)
        self.command_pub.publish(Float64(data=u))
        wall = time.time_ns()
        self.answered += 1
        if self.trace is not None:
            self.trace.write(f"{self.answered} {y!r} {u!r} {wall}\n")
        if self.answered_pub is not None:
            if not self.command_pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT)):
                self.get_logger().warn(
                    f"command {self.answered} not acknowledged within {ACK_TIMEOUT:g} s")
            self.answered_pub.publish(UInt64(data=self.answered))

    def close(self) -> None:
        if self.trace is not None:
            self.trace.close()
            self.trace = None


@quiet_pipe
def main(args: Optional[list[str]] = None) -> int:
    """Entry point of ``pi_controller`` / ``ros2 run flexure_sim pi_controller``."""
    argv = sys.argv if args is None else args
    if any(a in ("-h", "--help") for a in argv[1:]):
        print("usage: pi_controller [--ros-args -p NAME:=VALUE ...]\n\nan example PI "
              "controller closing the loop around stage_node (one command per measurement); "
              "its parameters and topics: docs/controller_guide.md")
        return 0
    import rclpy
    from rclpy.executors import ExternalShutdownException

    node = None
    error = None
    try:
        rclpy.init(args=args)
        node = PIControllerNode()
        AnswerLoop(node, node.polled()).serve()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except StartupError as exc:
        error = str(exc)
    except Exception as exc:  # noqa: BLE001 - one line, never a traceback
        error = f"{type(exc).__name__}: {exc}"
    finally:
        if error is not None:  # before ROS is released, which can hang (`release`)
            print(f"pi_controller: error: {error}", file=sys.stderr, flush=True)
        if node is not None:
            node.close()
        release(rclpy, node)
    return 1 if error is not None else 0


if __name__ == "__main__":
    sys.exit(main())
