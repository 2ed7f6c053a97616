"""
A recorded run as typed time series, read in one streaming pass.

`load_run` reads a rosbag2 MCAP file written by ``stage_node`` (or by ``ros2 bag record`` of
the same topics) and keeps only what the tools use, as numeric arrays (`series`), never the
decoded messages: memory grows with the samples of those topics (8 bytes a value), not with
the file. Times are in seconds of simulation time (`timebase`), values in SI units:

- scalar topics (``std_msgs/Float64``): `Run.scalar` -> `Series` with values of shape (n,);
- hinge wrenches: `Run.wrenches` -> {hinge: Series (n, 3) of (moment, f_x, f_y)} (N m, N, N),
  the wrench the hinge exerts on its body B, in its frame b (docs/engine.md, "Conventions");
- body poses (``poses=True``): `Run.poses` -> {body: Series (n, 3) of (x, y, yaw)} in the root
  frame, from ``/bodies/<body>/pose`` or else from the ``/bodies/poses`` array and the body
  names of the ``flexure_sim`` metadata record.

Topic names are found under the run's namespace (the node's topics are relative, so a node
started in namespace ``/left`` records ``/left/output/displacement``); `find_namespace`
works it out and asks for ``--namespace`` when a file holds several stages.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np

from flexure_sim.recording import TopicInfo
from flexure_sim.recording.command_line import check_readable, open_log
from flexure_sim.recording.exceptions import EXIT_USAGE, RunError
from flexure_sim.topics import (
    CLOCK, COMMAND, COMMAND_VOLTAGE, DRIVE_FORCE, DRIVE_INPUT, METADATA_NAME, OUTPUT, POSE_ARRAY,
    body_pose, hinge_compression, hinge_wrench,
)
from flexure_sim.tools.run.run_channels import (
    DriveChannel, OutputChannel, drive_channels, output_channels,
)
from flexure_sim.tools.run.mechanism_reload import (
    hinge_frame_displacements, load_recorded_mechanism,
)
from flexure_sim.tools.run.command_counts import tallied, tally
from flexure_sim.tools.run.series import CLOCK_TYPE, FLOAT64, Series, SeriesBuilder
from flexure_sim.tools.run.timebase import TimeBase, time_base

#: Topics whose presence marks the namespace of a stage run.
_MARKERS = (OUTPUT, DRIVE_INPUT, POSE_ARRAY, DRIVE_FORCE)
#: Topics (relative to the run's namespace) the time series are taken from.
_SIGNALS = (OUTPUT, DRIVE_INPUT, COMMAND, COMMAND_VOLTAGE, DRIVE_FORCE)
#: Leaves of the per-drive topics ``drive/<name>/<leaf>`` (several drives: `channels`).
_DRIVE_LEAVES = ("input", "force", "position", "displacement", "voltage")


@dataclass
class Run:
    """
    A run's topics, metadata and time series (arrays of log times and values per topic).

    ``raw`` maps a topic to (log times ns, values, row lengths or None) as `SeriesBuilder`
    made them; the typed views below turn them into `Series` in simulation time.
    """

    path: Path
    topics: dict[str, TopicInfo]
    metadata_records: tuple[tuple[str, dict[str, str]], ...]
    raw: dict[str, tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]]
    start_log_ns: int
    end_log_ns: int
    complete: bool = True
    note: str = ""
    undecodable: dict[str, int] = field(default_factory=dict)
    namespace: str = ""
    with_poses: bool = True
    #: Diagnostics and rejected-command channels: last values, message counts (`command_counts`).
    tallies: dict[str, Any] = field(default_factory=dict)
    _cache: dict[str, Any] = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------ file level
    @property
    def metadata(self) -> dict[str, str]:
        """Return the ``flexure_sim`` metadata record (mechanism, parameters), empty if absent."""
        records = [d for name, d in self.metadata_records if name == METADATA_NAME]
        return dict(records[-1]) if records else {}

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
        return self.topic(relative) in self.topics

    # ------------------------------------------------------------------ time base
    @property
    def timebase(self) -> TimeBase:
        if "timebase" not in self._cache:
            clock = self.raw.get(CLOCK)
            self._cache["timebase"] = time_base(*clock[:2]) if clock else TimeBase()
        return self._cache["timebase"]

    @property
    def clock_mapped(self) -> bool:
        """
        Return True when log times are not simulation time and the recorded /clock maps them to it.

        E.g. ``ros2 bag record`` without ``--use-sim-time`` of a fast-mode run.
        """
        return self.timebase.mapped

    @property
    def start_ns(self) -> int:
        """First message time (simulation time, ns)."""
        return int(self.timebase.sim_ns(np.array([self.start_log_ns]))[0])

    @property
    def end_ns(self) -> int:
        """Last message time (simulation time, ns)."""
        return int(self.timebase.sim_ns(np.array([self.end_log_ns]))[0])

    # ------------------------------------------------------------------ typed views
    def _raw(self, relative: str, expected: str) -> tuple[np.ndarray, np.ndarray, Any]:
        name = self.topic(relative)
        found = self.topics[name].type
        if found != expected:
            raise RunError(f"{self.path}: {name} does not hold the expected fields (type "
                           f"{found}, expected {expected})")
        if name in self.raw:
            return self.raw[name]
        return SeriesBuilder(expected).arrays()  # no message read on this topic

    def scalar(self, relative: str) -> Optional[Series]:
        """Return a ``std_msgs/Float64`` topic as a Series of shape (n,), or None if absent."""
        if not self.has(relative):
            return None
        t, values, _ = self._raw(relative, FLOAT64)
        return Series(self.timebase.seconds(t), values)

    def _names_under(self, prefix: str, leaf: str) -> set[str]:
        found = set()
        for name in self.topics:
            if name.startswith(prefix):
                parts = name[len(prefix):].split("/")
                if len(parts) == 2 and parts[1] == leaf:
                    found.add(parts[0])
        return found

    def hinge_names(self) -> list[str]:
        """Hinges with a wrench or deflection topic, in metadata order if known."""
        prefix = self.topic("hinges/")
        found = self._names_under(prefix, "wrench") | self._names_under(prefix, "deflection")
        return _ordered(found, self.metadata.get("hinges", ""))

    def body_names(self) -> list[str]:
        """Bodies with a pose topic (or the metadata's list if only the array was recorded)."""
        found = self._names_under(self.topic("bodies/"), "pose")
        listed = [b for b in self.metadata.get("bodies", "").split(",") if b]
        if not found and self.has(POSE_ARRAY) and listed:
            return listed
        return _ordered(found, ",".join(listed))

    def compression_topic(self) -> Optional[str]:
        """Relative name of the ``hinges/<h>/compression`` topic, if recorded."""
        hinges = self._names_under(self.topic("hinges/"), "compression")
        return hinge_compression(sorted(hinges)[0]) if hinges else None

    def compression_hinge(self) -> Optional[str]:
        topic = self.compression_topic()
        return topic.split("/")[1] if topic else None

    def wrenches(self, every_component: bool = False) -> dict[str, Series]:
        """
        Return each hinge's wrench series: (moment z, f_x, f_y).

        ``every_component``: of a run of the spatial engine, then (moment x, moment y, f_z)
        too (``series``).
        """
        out = {}
        for h in self.hinge_names():
            rel = hinge_wrench(h)
            if self.has(rel):
                t, values, _ = self._raw(rel, "geometry_msgs/msg/WrenchStamped")
                out[h] = Series(self.timebase.seconds(t),
                                values if every_component else values[:, :3])
        return out

    def poses(self) -> dict[str, Series]:
        """Pose (x, y, yaw) of every body in the root frame, per body."""
        if not self.with_poses:
            raise RuntimeError("Run.poses: the run was loaded without them (load_run(poses=True))")
        if "poses" in self._cache:
            return self._cache["poses"]
        out: dict[str, Series] = {}
        bodies = self.body_names()
        for b in bodies:
            rel = body_pose(b)
            if self.has(rel):
                t, values, _ = self._raw(rel, "geometry_msgs/msg/PoseStamped")
                out[b] = Series(self.timebase.seconds(t), values)
        if not out and self.has(POSE_ARRAY) and bodies:
            t, flat, lengths = self._raw(POSE_ARRAY, "geometry_msgs/msg/PoseArray")
            bad = np.nonzero(lengths != 3 * len(bodies))[0]
            if bad.shape[0]:
                raise RunError(
                    f"{self.path}: {self.topic(POSE_ARRAY)} holds poses of "
                    f"{int(lengths[bad[0]]) // 3} bodies, the metadata names {len(bodies)} "
                    f"({', '.join(bodies)})")
            arr = flat.reshape(t.shape[0], len(bodies), 3)
            seconds = self.timebase.seconds(t)
            out = {b: Series(seconds, arr[:, i, :]) for i, b in enumerate(bodies)}
        self._cache["poses"] = out
        return out

    def drives(self) -> list[DriveChannel]:
        """Return the drives of the run, with their topics and units (`channels`)."""
        if "drives" not in self._cache:
            self._cache["drives"] = drive_channels(self.topics, self.topic, self.metadata,
                                                   self.mechanism())
        return self._cache["drives"]

    def outputs(self) -> list[OutputChannel]:
        """Return the outputs of the run, with their topics and units (`channels`)."""
        if "outputs" not in self._cache:
            self._cache["outputs"] = output_channels(self.topics, self.topic, self.metadata,
                                                     self.mechanism())
        return self._cache["outputs"]

    # ------------------------------------------------------------------ mechanism
    def mechanism(self) -> Any:
        """
        Return the mechanism the run simulated (engine/mechanism/parts.Mechanism), or None.

        `mechanism_problem` says why it is None (`load_recorded_mechanism`).
        """
        if "mechanism" not in self._cache:
            self._cache["mechanism"], self._cache["mechanism_problem"] = (
                load_recorded_mechanism(self.metadata))
        return self._cache["mechanism"]

    @property
    def mechanism_problem(self) -> str:
        self.mechanism()
        return self._cache["mechanism_problem"]

    def hinge_frame_displacements(
        self, hinge: str
    ) -> Optional[tuple[np.ndarray, np.ndarray, np.ndarray, str, str]]:
        """
        Return `mechanism_reload.hinge_frame_displacements` of this run.

        None without the mechanism or the poses.
        """
        mech = self.mechanism()
        if mech is None:
            return None
        return hinge_frame_displacements(mech, hinge, self.poses())


def _ordered(found: set[str], listed: str) -> list[str]:
    order = [x for x in listed.split(",") if x in found]
    return order + sorted(found - set(order))


def find_namespace(log: Any, requested: Optional[str] = None) -> str:
    """
    Return the namespace of the stage run in ``log`` ('' for the root).

    Uses the log's ``path`` and ``topics``. ``requested`` (``--namespace``) is checked; otherwise
    it is inferred from the topics ending in output/displacement, drive/input, bodies/poses or
    drive/force.
    """
    path, topics = log.path, set(log.topics)
    if requested is not None:
        ns = "/" + requested.strip("/") if requested.strip("/") else ""
        if not any(f"{ns}/{m}" in topics for m in _MARKERS):
            raise RunError(f"{path}: no stage topics under namespace {ns or '/'!r} "
                           f"(topics: {', '.join(sorted(topics)) or 'none'})", EXIT_USAGE)
        return ns
    found = set()
    for name in topics:
        for marker in _MARKERS:
            if name.endswith("/" + marker):
                found.add(name[: -len(marker) - 1])
        parts = name.split("/")
        if len(parts) >= 4 and ((parts[-3], parts[-1]) == ("drive", "input")
                                or (parts[-3], parts[-1]) == ("output", "displacement")):
            found.add("/".join(parts[:-3]))  # drive/<name>/input, output/<name>/displacement
    if len(found) > 1:
        stages = ", ".join(sorted(n or "/" for n in found))
        raise RunError(f"{path}: topics of several stages ({stages}); choose one with "
                       "--namespace", EXIT_USAGE)
    return found.pop() if found else ""


def _wanted(name: str, namespace: Optional[str], poses: bool) -> bool:
    """
    Whether the series of topic ``name`` are needed.

    /clock, the signals, hinge wrenches and compressions and (``poses``) body poses of the stage in
    ``namespace`` (of any stage when the namespace is not known yet).
    """
    if name == CLOCK:
        return True
    if namespace is None:
        parts = name.lstrip("/").split("/")  # any prefix of the name may be the namespace
        candidates = ["/".join(parts[k:]) for k in range(len(parts))]
    else:
        prefix = namespace + "/"
        if not name.startswith(prefix):
            return False
        candidates = [name[len(prefix):]]
    return any(_needed(rel, poses) for rel in candidates)


def _needed(rel: str, poses: bool) -> bool:
    """Whether ``rel``, a topic name relative to a stage's namespace, is read."""
    parts = rel.split("/")
    if rel in _SIGNALS:
        return True
    if len(parts) == 3 and parts[0] == "hinges" and parts[2] in ("wrench", "compression"):
        return True
    if len(parts) == 3 and ((parts[0] == "drive" and parts[2] in _DRIVE_LEAVES)
                            or (parts[0] == "output" and parts[2] == "displacement")):
        return True
    return poses and (rel == POSE_ARRAY or (len(parts) == 3 and parts[0] == "bodies"
                                            and parts[2] == "pose"))


def load_run(
    path: str | os.PathLike[str],
    recover: bool = False,
    namespace: Optional[str] = None,
    strict: bool = False,
    poses: bool = True,
) -> Run:
    """
    Read ``path`` (strictly, or its readable part with ``recover``) as a stage run.

    Keeping the series of the signals, the hinge wrenches and compression, /clock and, with
    ``poses``, the body poses (analyse needs no poses: reading them costs time).
    """
    reader = open_log(path, recover=recover, strict=strict)
    ns: Optional[str] = None
    if reader.summary_ok:  # topics known before the pass: read only this stage's
        ns = find_namespace(reader, namespace)
    builders: dict[str, SeriesBuilder] = {}
    # A run of the spatial engine: hinge wrenches with all six components (`series`).
    spatial = reader.metadata.get(METADATA_NAME, {}).get("space") == "3d"
    tallies: dict[str, Any] = {}

    def select(topic: TopicInfo) -> bool:
        if tallied(topic.name, topic.type, ns):
            tallies[topic.name] = 0
            return True
        if not SeriesBuilder.supports(topic.type) or not _wanted(topic.name, ns, poses):
            return False
        if topic.name == CLOCK and topic.type != CLOCK_TYPE:
            return False
        builders[topic.name] = SeriesBuilder(topic.type, spatial)
        return True

    for m in reader.messages(select):
        if m.topic in tallies:
            tallies[m.topic] = tally(tallies[m.topic], m.message)
        else:
            builders[m.topic].add(m.log_time_ns, m.message)
    check_readable(reader)
    if ns is None:
        ns = find_namespace(reader, namespace)
    return Run(
        path=Path(path),
        topics=reader.topics,
        metadata_records=reader.metadata_records,
        raw={name: b.arrays() for name, b in builders.items()},
        start_log_ns=reader.start_ns,
        end_log_ns=reader.end_ns,
        complete=reader.complete,
        note=reader.note,
        undecodable=dict(reader.undecodable),
        namespace=ns,
        with_poses=poses,
        tallies=tallies,
    )


def require_stage_run(run: Run, what: str) -> None:
    """Raise RunError unless the run has the topics ``what`` needs (output, drive input)."""
    missing = [run.topic(t) for t in (OUTPUT, DRIVE_INPUT) if not run.has(t)]
    if missing and run.drives() and run.outputs():
        return  # several drives or outputs: drive/<name>/input, output/<name>/displacement
    if missing:
        mech = f" (mechanism {run.mechanism_name})" if run.mechanism_name else ""
        raise RunError(
            f"{run.path}: {what} needs the topics {', '.join(missing)}, which this run{mech} "
            f"does not have; its topics: {', '.join(sorted(run.topics)) or 'none'}")
