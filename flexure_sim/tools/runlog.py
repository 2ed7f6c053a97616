"""A recorded run as typed time series, and the one place where bad files become messages.

`load_run` reads a rosbag2 MCAP file written by ``stage_node`` (or by ``ros2 bag record`` of
the same topics) and gives per-topic arrays: times in seconds (the MCAP log time, which the
node sets to the simulation time stamp) and values in SI units:

- scalar topics (``std_msgs/Float64``): `Run.scalar` -> `Series` with values of shape (n,);
- hinge wrenches: `Run.wrenches` -> {hinge: Series (n, 3) of (moment, f_x, f_y)} (N m, N, N),
  the wrench the hinge exerts on its body B, in its frame b (README, "Conventions");
- hinge deflections: `Run.deflections` -> {hinge: Series (n, 3) of (alpha, p_x, p_y)};
- body poses: `Run.poses` -> {body: Series (n, 3) of (x, y, yaw)} in the root frame, from
  ``/bodies/<body>/pose`` or else from the ``/bodies/poses`` array and the body names of the
  ``flexure_sim`` metadata record.

Topic names are found under the run's namespace (the node's topics are relative, so a node
started in namespace ``/left`` records ``/left/output/displacement``); `find_namespace`
works it out and asks for ``--namespace`` when a file holds several stages.

Error handling: every tool wraps its work in `tool_errors`, which turns `CorruptLogError`
(empty, truncated, damaged or non-ROS files), `RunError` and OS errors into one line on stderr
naming the file and the problem (how much of it was readable, and that ``--recover`` reads
that part) and an exit code: 1 for a bad or unusable file, 2 for bad usage. No traceback
reaches the user, whatever the file holds.
"""
from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ..errors import FlexureSimError
from ..recording import CorruptLogError, McapLog, read_log
# Topic names of a stage run, relative to its namespace, and the metadata record names
# (re-exported for the tools).
from ..topics import (  # noqa: F401
    CLOCK, COMMAND, DRIVE_FORCE, DRIVE_INPUT, METADATA_NAME, OUTPUT, PARAMETER_CHANGE_NAME, POSE_ARRAY,
    body_pose, hinge_compression, hinge_deflection, hinge_wrench,
)
from ..recording.errors import RecordingError

#: Exit codes of every tool.
EXIT_OK = 0
EXIT_BAD_FILE = 1
EXIT_USAGE = 2

#: Log times further than this from the /clock values they carry are not simulation time.
CLOCK_MISMATCH_NS = 500_000_000
#: Topics whose presence marks the namespace of a stage run.
_MARKERS = (OUTPUT, DRIVE_INPUT, POSE_ARRAY, DRIVE_FORCE)


class RunError(FlexureSimError):
    """A file that reads but cannot be used as asked (missing topics...), or bad usage.

    ``exit_code`` is `EXIT_BAD_FILE` or `EXIT_USAGE`.
    """

    def __init__(self, message: str, exit_code: int = EXIT_BAD_FILE) -> None:
        super().__init__(message)
        self.exit_code = exit_code


@dataclass(frozen=True)
class Series:
    """Samples of one topic: ``t`` (s, MCAP log time = simulation time) and ``values``."""

    t: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def empty(self) -> bool:
        return self.t.shape[0] == 0


@dataclass
class Run:
    """A loaded log and the typed views of its topics (computed on first use)."""

    path: Path
    log: McapLog
    namespace: str = ""
    _cache: dict[str, Any] = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------ file level
    @property
    def complete(self) -> bool:
        return self.log.complete

    @property
    def note(self) -> str:
        """How much of a damaged file was recovered (empty for a complete file)."""
        return self.log.note

    @property
    def metadata(self) -> dict[str, str]:
        """The ``flexure_sim`` metadata record (mechanism, parameters), empty if absent."""
        return dict(self.log.metadata.get(METADATA_NAME, {}))

    @property
    def parameter_changes(self) -> list[dict[str, str]]:
        """Parameter changes recorded during the run (each with its sim time ``t``)."""
        return [dict(d) for name, d in self.log.metadata_records if name == PARAMETER_CHANGE_NAME]

    @property
    def mechanism_name(self) -> str:
        meta = self.metadata
        return meta.get("mechanism_name") or meta.get("mechanism") or ""

    def topic(self, relative: str) -> str:
        """Absolute name of a topic of the run (``relative`` under the run's namespace)."""
        if relative.startswith("/"):
            return relative
        return f"{self.namespace}/{relative}"

    def has(self, relative: str) -> bool:
        return self.topic(relative) in self.log.topics

    def messages(self, relative: str) -> list[Any]:
        """(log time ns, decoded message) of a topic, in file order."""
        key = "msgs:" + self.topic(relative)
        if key not in self._cache:
            self._cache[key] = [(m.log_time_ns, m.message) for m in self.log.messages_on(self.topic(relative))]
        return self._cache[key]

    @property
    def start_ns(self) -> int:
        """First message time (simulation time, ns)."""
        return int(self.times_ns(np.array([min((m.log_time_ns for m in self.log.messages), default=0)]))[0])

    @property
    def end_ns(self) -> int:
        """Last message time (simulation time, ns)."""
        return int(self.times_ns(np.array([max((m.log_time_ns for m in self.log.messages), default=0)]))[0])

    # ------------------------------------------------------------------ time base
    @property
    def clock_mapped(self) -> bool:
        """True when log times are not simulation time (e.g. ``ros2 bag record`` without
        ``--use-sim-time`` of a fast-mode run) and the recorded /clock maps them to it."""
        return self._clock_map() is not None

    def _clock_map(self) -> Optional[tuple[np.ndarray, np.ndarray]]:
        if "clock_map" not in self._cache:
            self._cache["clock_map"] = None
            if CLOCK in self.log.topics:
                pairs = [(m.log_time_ns, m.message.clock.sec * 1_000_000_000 + m.message.clock.nanosec)
                         for m in self.log.messages_on(CLOCK) if m.message is not None]
                if pairs:
                    log_t = np.array([p[0] for p in pairs], dtype=np.int64)
                    sim_t = np.array([p[1] for p in pairs], dtype=np.int64)
                    # stage_node stamps log time = sim time; a recorder on the wall clock does not.
                    if float(np.median(np.abs(log_t - sim_t))) > CLOCK_MISMATCH_NS:
                        order = np.argsort(log_t, kind="stable")
                        self._cache["clock_map"] = (log_t[order], sim_t[order])
        return self._cache["clock_map"]

    def times_ns(self, log_times_ns: np.ndarray) -> np.ndarray:
        """Simulation time (ns) of messages logged at ``log_times_ns``: the log time itself, or,
        when `clock_mapped`, the last /clock value logged at or before it."""
        cmap = self._clock_map()
        log_times_ns = np.asarray(log_times_ns, dtype=np.int64)
        if cmap is None:
            return log_times_ns
        log_t, sim_t = cmap
        k = np.searchsorted(log_t, log_times_ns, side="right") - 1
        return sim_t[np.clip(k, 0, sim_t.shape[0] - 1)]

    def _seconds(self, msgs: list) -> np.ndarray:
        return self.times_ns(np.array([ns for ns, _ in msgs], dtype=np.int64)) / 1e9

    # ------------------------------------------------------------------ typed views
    def scalar(self, relative: str) -> Optional[Series]:
        """A ``std_msgs/Float64`` topic as a Series of shape (n,), or None if absent."""
        if not self.has(relative):
            return None
        return self._series(relative, lambda m: float(m.data), ())

    def hinge_names(self) -> list[str]:
        """Hinges with a wrench or deflection topic, in metadata order if known."""
        found = set()
        prefix = self.topic("hinges/")
        for name in self.log.topics:
            if name.startswith(prefix):
                parts = name[len(prefix):].split("/")
                if len(parts) == 2 and parts[1] in ("wrench", "deflection"):
                    found.add(parts[0])
        return _ordered(found, self.metadata.get("hinges", ""))

    def body_names(self) -> list[str]:
        """Bodies with a pose topic (or the metadata's list if only the array was recorded)."""
        found = set()
        prefix = self.topic("bodies/")
        for name in self.log.topics:
            if name.startswith(prefix):
                parts = name[len(prefix):].split("/")
                if len(parts) == 2 and parts[1] == "pose":
                    found.add(parts[0])
        listed = [b for b in self.metadata.get("bodies", "").split(",") if b]
        if not found and self.has(POSE_ARRAY) and listed:
            return listed
        return _ordered(found, ",".join(listed))

    def compression_topic(self) -> Optional[str]:
        """Relative name of the ``hinges/<h>/compression`` topic, if recorded."""
        prefix = self.topic("hinges/")
        for name in sorted(self.log.topics):
            if name.startswith(prefix) and name.endswith("/compression"):
                rest = name[len(prefix):].split("/")
                if len(rest) == 2:
                    return hinge_compression(rest[0])
        return None

    def compression_hinge(self) -> Optional[str]:
        topic = self.compression_topic()
        return topic.split("/")[1] if topic else None

    def wrenches(self) -> dict[str, Series]:
        out = {}
        for h in self.hinge_names():
            rel = hinge_wrench(h)
            if self.has(rel):
                out[h] = self._series(rel, lambda m: (m.wrench.torque.z, m.wrench.force.x, m.wrench.force.y), (3,))
        return out

    def deflections(self) -> dict[str, Series]:
        out = {}
        for h in self.hinge_names():
            rel = hinge_deflection(h)
            if self.has(rel):
                out[h] = self._series(rel, lambda m: (_yaw(m.transform.rotation), m.transform.translation.x,
                                                      m.transform.translation.y), (3,))
        return out

    def poses(self) -> dict[str, Series]:
        """Pose (x, y, yaw) of every body in the root frame, per body."""
        if "poses" in self._cache:
            return self._cache["poses"]
        out: dict[str, Series] = {}
        bodies = self.body_names()
        for b in bodies:
            rel = body_pose(b)
            if self.has(rel):
                out[b] = self._series(rel, lambda m: _pose(m.pose), (3,))
        if not out and self.has(POSE_ARRAY) and bodies:
            msgs = self.messages(POSE_ARRAY)
            t = self._seconds(msgs)
            rows = [[_pose(p) for p in m.poses] for _, m in msgs]
            if rows and any(len(r) != len(bodies) for r in rows):
                raise RunError(
                    f"{self.path}: {self.topic(POSE_ARRAY)} holds poses of "
                    f"{len(rows[0])} bodies, the metadata names {len(bodies)} ({', '.join(bodies)})")
            arr = np.array(rows, dtype=float).reshape(len(rows), len(bodies), 3)
            out = {b: Series(t, arr[:, i, :]) for i, b in enumerate(bodies)}
        self._cache["poses"] = out
        return out

    def _series(self, relative: str, get: Callable[[Any], Any], shape: tuple[int, ...]) -> Series:
        key = "series:" + self.topic(relative)
        if key not in self._cache:
            msgs = self.messages(relative)
            t = self._seconds(msgs)
            try:
                values = np.array([get(m) for _, m in msgs], dtype=float).reshape((len(msgs),) + shape)
            except (AttributeError, TypeError, ValueError) as exc:
                raise RunError(f"{self.path}: {self.topic(relative)} does not hold the expected "
                               f"fields ({type(exc).__name__}: {exc})") from None
            self._cache[key] = Series(t, values)
        return self._cache[key]

    # ------------------------------------------------------------------ mechanism
    def mechanism(self):
        """The mechanism the run simulated (flexure_sim.engine.mechanism.Mechanism), or None.

        Tried in order: the YAML text stored in the metadata (what actually ran), the file
        at the recorded path, the built-in of the recorded name. `mechanism_problem` says why
        it is None.
        """
        if "mechanism" not in self._cache:
            self._cache["mechanism"], self._cache["mechanism_problem"] = _load_mechanism(self.metadata)
        return self._cache["mechanism"]

    @property
    def mechanism_problem(self) -> str:
        self.mechanism()
        return self._cache["mechanism_problem"]

    def hinge_frame_displacements(self, hinge: str) -> Optional[tuple[np.ndarray, np.ndarray, np.ndarray, str, str]]:
        """Displacement from rest (root frame, m) of a hinge's frame on body A and on body B,
        from the recorded body poses and the mechanism's frame positions.

        Returns (t, disp_a (n, 2), disp_b (n, 2), body A, body B), or None when the mechanism
        or the poses of the two bodies are not available. The x difference of the two along
        the drive axis is the hinge's compression (Figure 6.4 for joint a).
        """
        from dataclasses import replace

        from ..engine.config import frame_pose_at_rest

        mech = self.mechanism()
        if mech is None:
            return None
        try:
            h = mech.hinges[mech.hinge_index(hinge)]
            body_a = mech.bodies[mech.body_index(h.a.body)]
            body_b = mech.bodies[mech.body_index(h.b.body)]
        except ValueError:
            return None
        poses = self.poses()
        if h.a.body not in poses or h.b.body not in poses:
            return None
        pa, pb = poses[h.a.body], poses[h.b.body]
        if pa.t.shape != pb.t.shape or not np.array_equal(pa.t, pb.t):
            return None

        def displacement(frame, body, series: Series) -> np.ndarray:
            rest = frame_pose_at_rest(frame, body)[0]
            return np.array([frame_pose_at_rest(frame, replace(body, pose=tuple(p)))[0] - rest
                             for p in series.values.tolist()]).reshape(len(series), 2)

        return (pa.t, displacement(h.a, body_a, pa), displacement(h.b, body_b, pb), h.a.body, h.b.body)


def _ordered(found: set[str], listed: str) -> list[str]:
    order = [x for x in listed.split(",") if x in found]
    return order + sorted(found - set(order))


def _yaw(q: Any) -> float:
    """Yaw of a quaternion (exact for the node's yaw-only quaternions)."""
    return 2.0 * math.atan2(q.z, q.w) if (q.x == 0.0 and q.y == 0.0) else math.atan2(
        2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _pose(p: Any) -> tuple[float, float, float]:
    return p.position.x, p.position.y, _yaw(p.orientation)


def _load_mechanism(meta: dict[str, str]):
    from ..engine.config import ConfigError, load_mechanism, mechanism_from_dict

    problems = []
    path = meta.get("mechanism_path", "")
    name = meta.get("mechanism_name") or meta.get("mechanism") or ""
    text = meta.get("mechanism_yaml", "")
    if not (text or path or name):
        return None, "the file has no flexure_sim metadata record naming the mechanism"
    if text:
        try:
            import yaml

            return mechanism_from_dict(yaml.safe_load(text), source=path or "<recorded YAML>"), ""
        except ConfigError as exc:
            problems.append(f"recorded YAML: {exc}")
        except Exception as exc:  # noqa: BLE001 - yaml.YAMLError and whatever else bad text raises
            problems.append(f"recorded YAML: {type(exc).__name__}: {exc}")
    for candidate in (path, name):
        if not candidate:
            continue
        try:
            return load_mechanism(candidate), ""
        except (ConfigError, OSError, ValueError) as exc:
            problems.append(str(exc))
    return None, "; ".join(problems)


def find_namespace(log: McapLog, requested: Optional[str] = None) -> str:
    """The namespace of the stage run in ``log`` ('' for topics at the root).

    ``requested`` (``--namespace``) is checked; otherwise it is inferred from the topics
    ending in output/displacement, drive/input, bodies/poses or drive/force.
    """
    topics = set(log.topics)
    if requested is not None:
        ns = "/" + requested.strip("/") if requested.strip("/") else ""
        if not any(f"{ns}/{m}" in topics for m in _MARKERS):
            raise RunError(f"{log.path}: no stage topics under namespace {ns or '/'!r} "
                           f"(topics: {', '.join(sorted(topics)) or 'none'})", EXIT_USAGE)
        return ns
    found = set()
    for name in topics:
        for marker in _MARKERS:
            if name.endswith("/" + marker):
                found.add(name[: -len(marker) - 1])
    if len(found) > 1:
        raise RunError(f"{log.path}: topics of several stages ({', '.join(sorted(n or '/' for n in found))}); "
                       "choose one with --namespace", EXIT_USAGE)
    return found.pop() if found else ""


def check_path(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.exists():
        raise RunError(f"{p}: no such file", EXIT_USAGE)
    if p.is_dir():
        raise RunError(f"{p}: is a directory, not an MCAP file", EXIT_USAGE)
    return p


def open_log(path: str | os.PathLike[str], recover: bool = False, decode: bool = True) -> McapLog:
    """`read_log` of a checked path; with ``recover`` a file with nothing readable still fails."""
    p = check_path(path)
    log = read_log(p, recover=recover, decode=decode)
    if not log.complete and not log.messages:
        raise RunError(f"{p}: nothing readable: {log.note}")
    return log


def load_run(path: str | os.PathLike[str], recover: bool = False, namespace: Optional[str] = None) -> Run:
    """Read ``path`` (strictly, or its readable part with ``recover``) as a stage run."""
    log = open_log(path, recover=recover)
    return Run(Path(path), log, find_namespace(log, namespace))


def require_stage_run(run: Run, what: str) -> None:
    """Raise RunError unless the run has the topics ``what`` needs (output, drive input)."""
    missing = [run.topic(t) for t in (OUTPUT, DRIVE_INPUT) if not run.has(t)]
    if missing:
        mech = f" (mechanism {run.mechanism_name})" if run.mechanism_name else ""
        raise RunError(
            f"{run.path}: {what} needs the topics {', '.join(missing)}, which this run{mech} does "
            f"not have; its topics: {', '.join(sorted(run.log.topics)) or 'none'}")


def warn(prog: str, message: str) -> None:
    print(f"{prog}: warning: {message}", file=sys.stderr)


def report_recovered(prog: str, run_or_log: Any) -> None:
    """Say on stderr that only part of a damaged file was read (``--recover``)."""
    note = getattr(run_or_log, "note", "")
    if note:
        warn(prog, f"{getattr(run_or_log, 'path', '')}: incomplete file: {note}")


@contextlib.contextmanager
def _no_broken_pipe() -> Iterator[None]:
    try:
        yield
    except BrokenPipeError:
        # Output piped into `head` & co.: stop quietly (and keep Python from complaining).
        with contextlib.suppress(Exception):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        raise


def tool_errors(prog: str, work: Callable[[], int], can_recover: bool = True) -> int:
    """Run ``work`` and turn every expected failure into a message and an exit code.

    ``can_recover``: the command has a ``--recover`` option the user did not give, so a
    damaged file with readable messages gets the hint to use it.
    """
    try:
        with _no_broken_pipe():
            return work()
    except CorruptLogError as exc:
        hint = ""
        if can_recover and exc.readable_messages:
            hint = "; --recover reads the readable part"
        print(f"{prog}: error: {_plain(exc)}{hint}", file=sys.stderr)
        return EXIT_BAD_FILE
    except RunError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except RecordingError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_FILE
    except BrokenPipeError:
        return EXIT_OK
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:
        name = f"{exc.filename}: " if exc.filename else ""
        print(f"{prog}: error: {name}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_FILE
    except Exception as exc:  # noqa: BLE001 - last resort: a message, never a traceback
        if os.environ.get("FLEXURE_SIM_DEBUG"):
            raise
        print(f"{prog}: error: unexpected {type(exc).__name__}: {exc} "
              "(set FLEXURE_SIM_DEBUG=1 for the traceback)", file=sys.stderr)
        return EXIT_BAD_FILE


def _plain(exc: CorruptLogError) -> str:
    """The error without the library's Python hint (``read_log(path, recover=True)``)."""
    text = str(exc)
    for marker in ("; read_log(", "; log_info("):
        if marker in text:
            text = text.split(marker)[0]
    return text


def add_file_arguments(parser: Any, recover: bool = True, namespace: bool = True) -> None:
    """The arguments every file tool shares: RUN.mcap, --recover, --namespace."""
    parser.add_argument("run", metavar="RUN.mcap", help="MCAP file recorded by stage_node (or ros2 bag record)")
    if recover:
        parser.add_argument("--recover", action="store_true",
                            help="read what is readable of a truncated or damaged file instead of failing")
    if namespace:
        parser.add_argument("--namespace", default=None,
                            help="namespace of the stage's topics when the file holds several (default: inferred)")


def format_si(value: Optional[float], unit: str, scale: float = 1.0, digits: int = 5) -> str:
    if value is None or not np.isfinite(value):
        return "-"
    return f"{value * scale:.{digits}g}" + (f" {unit}" if unit else "")


def time_unit(duration_s: float) -> tuple[str, float]:
    """Unit and scale for a time axis spanning ``duration_s``."""
    if duration_s < 2.0:
        return "ms", 1e3
    return "s", 1.0


def columns(rows: Sequence[Sequence[str]], header: Sequence[str], align: str = "") -> str:
    """A plain text table (first column left-aligned, the rest right-aligned)."""
    table = [list(header)] + [list(r) for r in rows]
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    out = []
    for k, r in enumerate(table):
        cells = []
        for i, cell in enumerate(r):
            left = (align[i] == "<") if i < len(align) else (i == 0)
            cells.append(cell.ljust(widths[i]) if left else cell.rjust(widths[i]))
        out.append("  ".join(cells).rstrip())
        if k == 0:
            out.append("  ".join("-" * w for w in widths))
    return "\n".join(out)
