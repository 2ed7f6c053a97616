"""
``stage_node``: the executable of the stage node (`shell.StageNode`).

    ros2 run flexure_sim stage_node [--ros-args -p mechanism:=<name|file.yaml> -p NAME:=VALUE]

`main` follows the ros2 demos' idiom (``rclpy.init``, the node, spin, ``destroy_node`` and
``try_shutdown``); `Run` holds what it started and how it ends, with one-line endings
(docs/node.md): exit 0 after SIGINT or SIGTERM (the recording finished), 1 when the node
cannot start or the simulation stopped, 2 for bad command-line arguments; never a traceback,
whenever a signal lands.

Signals (`SignalGuard`): the handler is installed before anything heavy is imported. During
start-up the first SIGINT/SIGTERM aborts it (an exception from the handler); while the node
runs, rclpy's own handler shuts the context down, which ends the spin; from the moment
start-up ends (successfully or not) until exit, signals are only noted, so the exit — the
error message, finishing the recording — is never cut short. The handler raises at most
once, and the code that can receive that exception is all inside one ``try``; a signal that
lands in a Python function C code calls back, where an exception would be printed and lost,
is sent again (`FOREIGN_CALLBACKS`).
"""
from __future__ import annotations

import gc
import os
import signal
import sys
import threading
from typing import Any, Optional

from flexure_sim.console import quiet_pipe
from flexure_sim.errors import FlexureSimError
from flexure_sim.node.release import EXIT_GRACE_S, exit_deadline

#: GIL switch interval: keeps the stepping thread's latency low while callbacks run.
SWITCH_INTERVAL_S = 0.0005
SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: Python functions that C code calls back while the node starts: an exception raised in one
#: does not propagate (ctypes prints "Exception ignored ..." with a traceback and goes on).
#: llvmlite's object-cache hooks run them while Numba compiles the kernels (the first start
#: after an install): a Ctrl-C landing there printed a traceback and did not stop start-up.
FOREIGN_CALLBACKS = frozenset({"_raw_object_cache_notify", "_raw_object_cache_getbuffer"})
#: Seconds after which a signal that landed in such a callback is sent again (`SignalGuard`).
RESEND_S = 0.01

USAGE = """usage: stage_node [--ros-args -p NAME:=VALUE ...]

Simulates a flexure mechanism, planar or in space (default: the built-in micropositioning
stage) and publishes its state; see docs/node.md for topics, frames and QoS.

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

    def _handle(self, signum: int, frame: Any) -> None:
        if self.received is None:
            self.received = signum
        if self.starting:
            if _in_foreign_callback(frame):
                # Raised here it would be printed and lost: the signal comes again shortly,
                # to land in code that can take the exception (or after start-up: noted).
                timer = threading.Timer(RESEND_S, os.kill, (os.getpid(), signum))
                timer.daemon = True
                timer.start()
                return
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


def _in_foreign_callback(frame: Any) -> bool:
    """Whether ``frame`` runs within one of the `FOREIGN_CALLBACKS`."""
    while frame is not None:
        if frame.f_code.co_name in FOREIGN_CALLBACKS:
            return True
        frame = frame.f_back
    return False


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


class Done(BaseException):
    """The command line asked for no node (``--help``): exit with ``code``."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def command_line(args: Optional[list[str]]) -> list[str]:
    """
    Return the arguments for ``rclpy.init``; Done after ``--help``, UsageError if malformed.

    Only ROS arguments are accepted (``--ros-args -p NAME:=VALUE``): rclpy's own parser checks
    them (any failure of it is a bad argument: rclpy names its error type in no public module).
    """
    from rclpy.utilities import remove_ros_args

    argv = sys.argv if args is None else args
    if any(a in ("-h", "--help") for a in argv[1:]):
        print(_usage())
        raise Done(0)
    try:
        user_args = remove_ros_args(argv)[1:]
    except Exception as exc:  # noqa: BLE001 - rclpy's RCLInvalidROSArgsError
        raise UsageError(f"{exc} (see --help)") from None
    if user_args:
        raise UsageError(f"unexpected arguments {user_args}; parameters go after --ros-args as "
                         "-p NAME:=VALUE (see --help)")
    return argv


class Run:
    """
    What `main` started, and how it ends (module docstring).

    The signal guard is installed at construction; `failed` turns what ended the run into a
    message and an exit code, `end` finishes the recording, releases ROS and prints the one
    line.
    """

    def __init__(self) -> None:
        self.guard = SignalGuard()
        self.guard.install()
        self.rclpy: Any = None
        self.node: Any = None
        self.error: Optional[str] = None
        self.code = 0
        self._threads: set[int] = set()
        #: What ended the run, kept until `end` releases it: its traceback may hold a node
        #: that failed half-built, whose release can hang (`exit_deadline`).
        self.exc: Optional[BaseException] = None

    def init(self, argv: list[str]) -> None:
        """``rclpy.init`` with rclpy's signal handlers on top of the guard's."""
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        from flexure_sim.node.stage.pacing import process_threads

        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self.rclpy = rclpy
        self._threads = process_threads()
        # A signal shuts the context down (ending spin_until_stopped), then reaches the guard.
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.ALL)

    def started(self, node: Any) -> Any:
        """Start-up is over: ``node`` runs; the middleware's threads get its stepping niceness."""
        from flexure_sim.node.stage.pacing import process_threads

        self.node = node
        python = {thread.native_id for thread in threading.enumerate()}
        node.adopt_middleware_threads(process_threads() - self._threads - python)
        self.guard.started()
        return node

    def failed(self, exc: BaseException) -> None:
        """Take note of what ended the run."""
        self.exc = exc
        if isinstance(exc, Done):
            self.code = exc.code
        elif isinstance(exc, Interrupted):
            self.error = _startup_error(exc.__context__)
        elif isinstance(exc, UsageError):
            self.error, self.code = str(exc), 2
        elif isinstance(exc, Exception):
            self.error = _startup_error(exc)
            if self.error is None and self.guard.received is None:
                self.error = f"{type(exc).__name__}: {exc}"
        # KeyboardInterrupt (a handler other than the guard's, none expected): as SIGINT.

    def end(self) -> int:
        """
        Finish the recording, release ROS, print the one line; return the exit code.

        A reason known before ROS is released is printed first: releasing it can hang
        (`exit_deadline`, which then ends the process).
        """
        self.guard.started()
        said = self.error is not None
        if said:
            print(f"stage_node: error: {self.error}", file=sys.stderr, flush=True)
        if self.rclpy is not None or self.node is not None:
            try:
                if _clean_up(self):
                    self.code = 1
            except Exception as exc:  # noqa: BLE001 - still one line
                self.error = self.error or f"while shutting down: {type(exc).__name__}: {exc}"
        if self.error is not None:
            if not said:
                print(f"stage_node: error: {self.error}", file=sys.stderr)
            self.code = max(self.code, 1)
        elif self.guard.received is not None:
            when = " during start-up" if self.node is None else ""
            print(f"stage_node: stopped by {self.guard.name}{when}", file=sys.stderr)
        _ignore_signals()
        return self.code


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


def _clean_up(run: Run) -> bool:
    """
    Finish the recording and release ROS; True if the simulation had failed.

    The recording first, with no deadline; then ROS (the node, a node that failed half-built
    with the exception that holds it, the context) within `EXIT_GRACE_S` (`exit_deadline`).
    """
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
    with exit_deadline(EXIT_GRACE_S):
        if run.exc is not None:
            run.exc = None
            gc.collect()  # a half-built node in a reference cycle goes now, not at exit
        if node is not None:
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
    run = Run()  # before anything heavy is imported: signals from here on
    try:
        try:
            argv = command_line(args)
            from flexure_sim.node.stage.main_loop import spin
            from flexure_sim.node.stage.shell import StageNode

            run.init(argv)  # rclpy.init
            spin(run.started(StageNode()))
        finally:
            run.guard.started()  # the exception the guard may raise can only land before this
    except (Done, Interrupted, KeyboardInterrupt, Exception) as exc:
        run.failed(exc)
    return run.end()


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
