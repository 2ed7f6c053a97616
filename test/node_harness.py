"""
Helpers of the stage_node tests.

The node as a real subprocess, and a real rclpy peer node (its own context and DDS domain) that
publishes commands, subscribes and calls services.

DDS stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST). Every node test gets
its own domain id, derived from the run's ROS_DOMAIN_ID (scripts/run_tests.sh picks a random
one), so tests and concurrent runs do not hear each other. Under pytest-xdist each worker
draws from its own share of the domains (`next_domain_id`), so two workers never meet on one.
"""
from __future__ import annotations

import itertools
import os
import random
import signal
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable, Iterable, Optional, Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from flexure_sim.node.publish.interface import value_text

ROOT = Path(__file__).resolve().parent.parent
_BASE_DOMAIN = int(os.environ.get("ROS_DOMAIN_ID") or random.randint(1, 100))
#: pytest-xdist worker k of n (gw<k>; a plain run is worker 0 of 1) uses the domains k + 1 + n i.
_WORKER = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:])
_WORKERS = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
_SHARE = 100 // _WORKERS
_offsets = itertools.count(1)
#: Bound on the first start of a freshly installed copy of the package (colcon, pip, ros2 run):
#: it compiles the engine's kernels into that copy's cache ("up to a minute", the node says) on a
#: machine perhaps 5x slower and busy (the suite's other worker included). It only ends a hang.
FIRST_START_TIMEOUT = 300.0


def next_domain_id() -> int:
    """
    Return a fresh domain id in 1..100 for one test: the next of this worker's share.

    Steps of 37 (a prime, so prime to the share's size) cycle through the whole share from the
    run's base before one comes back.
    """
    return 1 + _WORKER + _WORKERS * ((_BASE_DOMAIN + 37 * next(_offsets)) % _SHARE)


def run_python(script: str) -> subprocess.CompletedProcess:
    """Run ``script`` in a fresh interpreter that imports this checkout; output captured."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env=env, cwd="/", timeout=60)


def proc_stat(path: str | Path) -> tuple[str, list[str]]:
    """(name, fields) of a /proc stat file; ``fields[k]`` is field k + 3 of proc(5)."""
    text = Path(path).read_text()
    return text[text.index("(") + 1:text.rindex(")")], text[text.rindex(")") + 2:].split()


def thread_stats(pid: int) -> list[tuple[str, list[str]]]:
    """`proc_stat` of every thread of process ``pid``, its main thread first."""
    tids = sorted(os.listdir(f"/proc/{pid}/task"), key=lambda t: (int(t) != pid, int(t)))
    return [proc_stat(f"/proc/{pid}/task/{tid}/stat") for tid in tids]


def node_env(domain_id: int, **extra: str) -> dict[str, str]:
    env = dict(os.environ)
    # The test process's fast-acknowledgement profile (conftest) is for its own peers only.
    env.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
    env.update(
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        PYTHONUNBUFFERED="1",
        RCUTILS_COLORIZED_OUTPUT="0",
        # A process that hangs is sent SIGABRT (`NodeProcess.wait`): Python's faulthandler
        # then writes every thread's stack to its stderr, which the failure shows.
        PYTHONFAULTHANDLER="1",
    )
    env.update(extra)
    return env


class NodeProcess:
    """
    ``stage_node`` run as a subprocess in ``cwd`` (output captured to files there).

    By default it runs the source tree (``python -m flexure_sim.node.stage.stage_node`` with the
    repository on PYTHONPATH); ``command`` runs something else (console script, launcher).
    """

    def __init__(
        self,
        cwd: Path,
        domain_id: int,
        params: Optional[dict[str, Any]] = None,
        command: Optional[Sequence[str]] = None,
        env: Optional[dict[str, str]] = None,
        extra_args: Sequence[str] = (),
    ) -> None:
        self.cwd = Path(cwd)
        self.cwd.mkdir(parents=True, exist_ok=True)
        args = list(command or [sys.executable, "-m", "flexure_sim.node.stage.stage_node"])
        args += list(extra_args)
        if params:
            args.append("--ros-args")
            for name, value in params.items():
                args += ["-p", f"{name}:={value_text(value)}"]
        if env is None:
            env = node_env(domain_id, PYTHONPATH=str(ROOT), ROS_LOG_DIR=str(self.cwd / "ros_log"))
        self.args = args
        self._out = open(self.cwd / "node.stdout", "wb")  # noqa: SIM115
        self._err = open(self.cwd / "node.stderr", "wb")  # noqa: SIM115
        self.proc = subprocess.Popen(
            args,
            cwd=self.cwd,
            env=env,
            stdout=self._out,
            stderr=self._err,
            stdin=subprocess.DEVNULL,
        )

    def alive(self) -> bool:
        return self.proc.poll() is None

    def send(self, sig: int) -> None:
        self.proc.send_signal(sig)

    def wait(self, timeout: float = 30.0) -> int:
        """
        Return the exit code; a process still running after ``timeout`` s is aborted.

        SIGABRT: its faulthandler (``node_env``) writes every thread's stack to its stderr,
        printed here (pytest shows it with the failure); then TimeoutExpired as before.
        """
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self._dump_stacks()
            raise
        finally:
            self._out.flush()
            self._err.flush()

    def _dump_stacks(self) -> None:
        if self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGABRT)
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=10)
        self._err.flush()
        print(f"{' '.join(self.args)} hung; its stderr, with the threads' stacks:\n"
              f"{self.stderr[-20000:]}", file=sys.stderr)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 30.0) -> int:
        if self.alive():
            self.send(sig)
        return self.wait(timeout)

    def kill(self) -> None:
        if self.alive():
            self.proc.kill()
            self.proc.wait(10)

    @property
    def stderr(self) -> str:
        return (self.cwd / "node.stderr").read_text(errors="replace")

    @property
    def stdout(self) -> str:
        return (self.cwd / "node.stdout").read_text(errors="replace")

    def wait_for_output(self, text: str, timeout: float = 60.0, stream: str = "stderr") -> str:
        """
        Wait until the node's ``stream`` holds a line containing ``text``; return that line.

        Fails at once with the output if the node exits first.
        """
        path = self.cwd / f"node.{stream}"
        end = time.monotonic() + timeout
        while True:
            exited = not self.alive()
            for line in path.read_text(errors="replace").splitlines():
                if text in line:
                    return line
            if exited:
                raise AssertionError(f"stage_node exited ({self.proc.returncode}) before printing "
                                     f"{text!r}:\n{self.stderr}")
            if time.monotonic() > end:
                raise AssertionError(
                    f"timed out after {timeout:g} s waiting for {text!r}:\n{self.stderr}"
                )
            time.sleep(0.01)  # polling interval of the file, not a synchronisation

    def children(self) -> list[int]:
        """Process ids of the node's child processes (its MCAP recorder)."""
        kids = []
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                fields = stat.read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            if int(fields[1]) == self.proc.pid:
                kids.append(int(stat.parent.name))
        return kids

    def recordings(self) -> list[Path]:
        return sorted(self.cwd.rglob("*.mcap"))


def reliable(depth: int = 1000) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


class Peer:
    """A real rclpy node in the test process, in its own context and domain."""

    def __init__(
        self, domain_id: int, name: str = "test_peer", use_sim_time: bool = False
    ) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        overrides = [Parameter("use_sim_time", Parameter.Type.BOOL, True)] if use_sim_time else []
        self.node = rclpy.create_node(name, context=self.context, parameter_overrides=overrides)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received: dict[str, list[tuple[Any, bytes]]] = defaultdict(list)
        self._types: dict[str, type] = {}
        #: A node process whose death ends every wait at once (with its output).
        self.watch: Optional[NodeProcess] = None
        self._step_clients: dict[str, Any] = {}

    # ---------------------------------------------------------------- topics
    def subscribe(self, topic: str, msg_type: type, depth: int = 1000,
                  qos: Optional[QoSProfile] = None) -> None:
        """Keep every message (decoded, raw bytes) received on ``topic`` (``qos``: reliable)."""
        self._types[topic] = msg_type
        store = self.received[topic]

        def callback(data: bytes) -> None:
            store.append((deserialize_message(data, msg_type), data))

        self.node.create_subscription(msg_type, topic, callback, qos or reliable(depth), raw=True)

    def messages(self, topic: str) -> list[Any]:
        return [m for m, _ in self.received[topic]]

    def last(self, topic: str) -> Any:
        items = self.received[topic]
        return items[-1][0] if items else None

    def last_data(self, topic: str) -> float:
        """
        Return the ``data`` of the last message on ``topic``, NaN before the first one arrives.

        For predicates of ``spin_until``: a tick topic is published only once the node has
        matched a subscriber, so its first message can come after other topics' (NaN compares
        false with every number; ``last(topic).data`` raised on None).
        """
        msg = self.last(topic)
        return float("nan") if msg is None else msg.data

    def publisher(self, topic: str, msg_type: type, depth: int = 1000):
        return self.node.create_publisher(msg_type, topic, reliable(depth))

    def publish_acked(self, publisher: Any, msg: Any, timeout: float = 30.0) -> None:
        """
        Publish ``msg`` and return once every matched reliable reader holds it.

        The stage's command reader then has it before the next ``~/step`` (lockstep): the
        synchronisation the node's README prescribes, not a sleep. Quick under the test
        process's 1 ms heartbeat profile (conftest).
        """
        from rclpy.duration import Duration

        publisher.publish(msg)
        if not publisher.wait_for_all_acked(Duration(seconds=timeout)):
            raise AssertionError(
                f"{publisher.topic_name}: not acknowledged by its readers within {timeout:g} s")

    # ---------------------------------------------------------------- spinning
    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def spin_until(
        self, predicate: Callable[[], bool], timeout: float, what: str = "condition"
    ) -> None:
        end = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > end:
                raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
            if self.watch is not None and not self.watch.alive():
                raise AssertionError(
                    f"stage_node exited ({self.watch.proc.returncode}) while waiting for "
                    f"{what}:\n{self.watch.stderr}"
                )
            self.executor.spin_once(timeout_sec=0.05)

    def wait_for_publishers(self, topics: Iterable[str], timeout: float = 20.0) -> None:
        topics = list(topics)
        self.spin_until(lambda: all(self.node.count_publishers(t) > 0 for t in topics), timeout,
                        f"publishers of {topics}")

    def wait_for_subscribers(self, publisher, timeout: float = 20.0) -> None:
        self.spin_until(lambda: publisher.get_subscription_count() > 0, timeout,
                        f"a subscriber of {publisher.topic_name}")

    # ---------------------------------------------------------------- lockstep ticks
    def connect_drive(self, topics: dict[str, type]) -> Any:
        """
        Subscribe ``topics`` ({name: message type}); publish the single drive's command.

        Returns the command publisher once the stage publishes every topic and reads it.
        """
        from std_msgs.msg import Float64

        for topic, msg_type in topics.items():
            self.subscribe(topic, msg_type)
        drive = self.publisher("/drive/displacement", Float64)
        self.wait_for_publishers(list(topics))
        self.wait_for_subscribers(drive)
        return drive

    def connect_drives(self, drives: Sequence[str], topics: Sequence[str],
                       kind: str = "displacement") -> dict[str, Any]:
        """
        Subscribe ``/clock`` and the Float64 ``topics``; publish each drive's command.

        Returns the command publishers (by drive) once the stage publishes ``topics`` and
        reads every command topic.
        """
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Float64

        self.subscribe("/clock", Clock)
        for topic in topics:
            self.subscribe(topic, Float64)
        commands = {d: self.publisher(f"/drive/{d}/{kind}", Float64) for d in drives}
        self.wait_for_publishers(topics)
        for publisher in commands.values():
            self.wait_for_subscribers(publisher)
        return commands

    def tick(self, topics: Sequence[str] = (), timeout: float = 30.0,
             service: str = "/stage_node/step") -> None:
        """
        Advance a lockstep stage by one tick through its ``~/step`` service; receive its messages.

        Returns once ``/clock`` (subscribed by the caller) and each of ``topics`` have one
        message more than ``/clock`` had before. The step client is kept for the peer's life:
        one discovery, not one per tick.
        """
        from std_srvs.srv import Trigger

        client = self._step_clients.get(service)
        if client is None:
            client = self._step_clients[service] = self.node.create_client(Trigger, service)
        self.spin_until(client.service_is_ready, timeout, f"service {service}")
        n = len(self.received["/clock"])
        future = client.call_async(Trigger.Request())
        self.spin_until(future.done, timeout, f"the answer of {service}")
        answer = future.result()
        assert answer.success, answer.message
        self.spin_until(lambda: len(self.received["/clock"]) > n
                        and all(len(self.received[t]) > n for t in topics), timeout,
                        "the tick's messages")

    def tick_until(self, predicate: Callable[[], bool], what: str,
                   topics: Sequence[str] = (), limit: int = 50) -> None:
        """Lockstep ticks (`tick`) until ``predicate`` holds after one (e.g. a command taken)."""
        for _ in range(limit):
            self.tick(topics)
            if predicate():
                return
        raise AssertionError(f"{what} not reached in {limit} ticks")

    # ---------------------------------------------------------------- services
    def call(self, srv_type: type, name: str, request: Any = None, timeout: float = 30.0) -> Any:
        client = self.node.create_client(srv_type, name)
        try:
            self.spin_until(lambda: client.service_is_ready(), timeout, f"service {name}")
            future = client.call_async(request if request is not None else srv_type.Request())
            self.spin_until(future.done, timeout, f"the answer of {name}")
            return future.result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def diagnostics_values(msg: Any) -> dict[str, str]:
    """Key/value pairs of the first status of a DiagnosticArray."""
    return {kv.key: kv.value for kv in msg.status[0].values}
