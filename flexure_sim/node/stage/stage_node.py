"""
``stage_node``: the executable of the stage node (`shell.StageNode`).

    ros2 run flexure_sim stage_node [--ros-args -p mechanism:=<name|file.yaml> -p NAME:=VALUE]

`main` follows the Jazzy idiom (``rclpy.init``, spin, ``destroy_node``, ``try_shutdown``) and
guarantees one-line endings (docs/node.md): exit 0 after SIGINT or SIGTERM (the
recording finished), 1 when the node cannot start or the simulation stopped, 2 for bad
command-line arguments; never a traceback, whenever a signal lands.

Signals (`SignalGuard`): the handler is installed before anything heavy is imported. During
start-up the first SIGINT/SIGTERM aborts it (an exception from the handler); while the node
runs, rclpy's own handler shuts the context down, which ends the spin; from the moment
start-up ends (successfully or not) until exit, signals are only noted, so the exit — the
error message, finishing the recording — is never cut short. The handler raises at most
once, and the code that can receive that exception is all inside one ``try``.
"""
from __future__ import annotations

import signal
import sys
import threading
from typing import Any, Optional

from flexure_sim.console import quiet_pipe
from flexure_sim.errors import FlexureSimError

#: GIL switch interval: keeps the stepping thread's latency low while callbacks run.
SWITCH_INTERVAL_S = 0.0005
SIGNALS = (signal.SIGINT, signal.SIGTERM)

USAGE = """usage: stage_node [--ros-args -p NAME:=VALUE ...]

Simulates a planar flexure mechanism (default: the built-in micropositioning stage) and
publishes its state; see docs/node.md for topics, frames and QoS.

parameters:
"""


class Interrupted(BaseException):
    """A signal arrived during start-up (raised by `SignalGuard`, once)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


class UsageError(FlexureSimError, ValueError):
    """Bad command-line arguments (exit code 2)."""


class SignalGuard:
    """SIGINT/SIGTERM handling of `main` (see the module docstring)."""

    def __init__(self) -> None:
        self.received: Optional[int] = None
        self.starting = True

    def install(self) -> None:
        for sig in SIGNALS:
            signal.signal(sig, self._handle)

    def _handle(self, signum: int, _frame: Any) -> None:
        if self.received is None:
            self.received = signum
        if self.starting:
            self.starting = False  # first and last raise
            raise Interrupted(signum)

    def started(self) -> None:
        """
        Start-up is over.

        From now on signals are only noted (rclpy's handler, installed on top of this one, ends the
        spin).
        """
        self.starting = False

    @property
    def name(self) -> str:
        return signal.Signals(self.received).name if self.received else ""


def _usage() -> str:
    from flexure_sim.node.params.table import parameter_specs

    lines = [USAGE]
    for spec in parameter_specs((0.0, 2e-6, 0.01)):
        unit = f" [{spec.unit}]" if spec.unit else ""
        default = ("mechanism's drive" if spec.name in ("stroke_min", "stroke_max", "slew_rate")
                   else repr(spec.default))
        read_only = ", read-only" if spec.read_only else ""
        lines.append(f"  {spec.name}{unit} (default {default}{read_only}):")
        lines.append(f"      {spec.description}")
    lines.append("\nservices: ~/reset (std_srvs/Trigger), ~/record (std_srvs/SetBool), "
                 "~/step (std_srvs/Trigger, lockstep mode)")
    return "\n".join(lines)


class _Run:
    """What `main` started, for the clean-up."""

    def __init__(self) -> None:
        self.rclpy: Any = None
        self.node: Any = None


def _user_args(argv: list[str]) -> list[str]:
    """Return the arguments that are not ROS arguments; UsageError if the ROS ones do not parse."""
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
    from rclpy.utilities import remove_ros_args

    try:
        return remove_ros_args(argv)[1:]
    except _rclpy.RCLInvalidROSArgsError as exc:
        raise UsageError(f"{exc} (see --help)") from None


def _start_and_spin(argv: list[str], run: _Run, guard: SignalGuard) -> None:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
    from rclpy.signals import SignalHandlerOptions

    from flexure_sim.node.stage.main_loop import spin_until_stopped
    from flexure_sim.node.stage.pacing import process_threads
    from flexure_sim.node.stage.shell import StageNode

    run.rclpy = rclpy
    # rclpy's handlers sit on top of the guard's: a signal shuts the context down (ending
    # spin_until_stopped), then reaches the guard.
    before = process_threads()
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.ALL)
    except _rclpy.RCLInvalidROSArgsError as exc:
        raise UsageError(f"{exc} (see --help)") from None
    run.node = StageNode()
    # The threads ROS started in this process: the middleware's (not Python's own).
    python = {thread.native_id for thread in threading.enumerate()}
    run.node.adopt_middleware_threads(process_threads() - before - python)
    guard.started()
    executor = SingleThreadedExecutor()
    executor.add_node(run.node)
    spin_until_stopped(executor, run.node.stopped, run.node.context)


def _startup_error(exc: Optional[BaseException]) -> Optional[str]:
    """
    Return the one-line reason of a start-up failure found in an exception chain.

    If any (no import: if `shell` is not loaded, no StartupError can have been raised).
    """
    startup_error = getattr(sys.modules.get(f"{__package__}.shell"), "StartupError", None)
    while exc is not None and startup_error is not None:
        if isinstance(exc, startup_error):
            return str(exc)
        exc = exc.__context__
    return None


def _clean_up(run: _Run) -> bool:
    """Finish the recording and release ROS; True if the simulation had failed."""
    failed = False
    node = run.node
    if run.rclpy is not None:
        try:
            from rclpy.signals import uninstall_signal_handlers

            uninstall_signal_handlers()  # the guard alone handles signals from here on
        except Exception:  # noqa: BLE001 - not installed
            pass
    if node is not None:
        node.shutdown()
        failed = node.failure is not None
        try:
            node.destroy_node()
        except Exception:  # noqa: BLE001 - the context is already gone
            pass
    if run.rclpy is not None:
        run.rclpy.try_shutdown()
    return failed


@quiet_pipe
def main(args: Optional[list[str]] = None) -> int:
    """Entry point of ``stage_node`` / ``ros2 run flexure_sim stage_node``."""
    guard = SignalGuard()
    guard.install()
    run = _Run()
    error: Optional[str] = None
    code = 0
    try:
        try:
            argv = sys.argv if args is None else args
            if any(a in ("-h", "--help") for a in argv[1:]):
                print(_usage())
                return _exit_now(0)
            user_args = _user_args(argv)
            if user_args:
                print(f"stage_node: error: unexpected arguments {user_args}; parameters go "
                      "after --ros-args as -p NAME:=VALUE (see --help)", file=sys.stderr)
                return _exit_now(2)
            sys.setswitchinterval(SWITCH_INTERVAL_S)
            _start_and_spin(argv, run, guard)
        finally:
            guard.started()  # the exception the guard may raise can only land before this
    except Interrupted as exc:
        error = _startup_error(exc.__context__)
    except KeyboardInterrupt:
        pass  # a handler other than the guard's (none expected): same as SIGINT
    except UsageError as exc:
        error, code = str(exc), 2
    except Exception as exc:  # noqa: BLE001 - one line, never a traceback
        error = _startup_error(exc)
        if error is None and guard.received is None:
            error = f"{type(exc).__name__}: {exc}"
    try:
        if _clean_up(run):
            code = 1
    except Exception as exc:  # noqa: BLE001 - still one line
        error = error or f"while shutting down: {type(exc).__name__}: {exc}"
    if error is not None:
        print(f"stage_node: error: {error}", file=sys.stderr)
        code = max(code, 1)
    elif guard.received is not None:
        when = " during start-up" if run.node is None else ""
        print(f"stage_node: stopped by {guard.name}{when}", file=sys.stderr)
    _ignore_signals()
    return code


def _exit_now(code: int) -> int:
    _ignore_signals()
    return code


def _ignore_signals() -> None:
    """
    Ignore SIGINT/SIGTERM in every thread until the process ends: the exit is decided.

    (At exit Python resets signals that have a Python handler to their default action, which would
    let a late Ctrl-C kill the process instead of letting it exit with its code; it leaves ignored
    ones alone.)
    """
    for sig in SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


if __name__ == "__main__":
    sys.exit(main())
