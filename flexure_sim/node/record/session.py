"""
Recordings of the stage node.

File names, metadata, and the session of files one node writes (`RecordingSession`).

Layout (`recording_layout`): a rosbag2 bag directory per recording (``record_format`` bag,
the default: ``<name>/metadata.yaml`` + ``<name>/<name>_0.mcap``...), or one MCAP file
(``record_format`` mcap, or a ``record_path`` ending in ``.mcap``).

Each recording holds a channel per published topic plus the drive command topic, and a
metadata record ``flexure_sim`` (mechanism, parameters, engine settings); the node records
the same CDR bytes it publishes (written by `record_process`).

Names are claimed, not just chosen: `claim_recording_path` creates the file with
``O_CREAT | O_EXCL`` (atomic on POSIX file systems, NFS v3+ included), so two nodes started in
the same second on one ``record_dir`` (as a launch file does) can never both take one name;
the loser moves on to the next suffix. Existing files are never overwritten.
"""
from __future__ import annotations

import datetime as _dt
import os
from pathlib import Path
from typing import Any, Iterator, Mapping, Optional, Sequence

from flexure_sim import __version__
from flexure_sim.engine.mechanism.parts import Mechanism
from flexure_sim.recording import RecordingError
from flexure_sim.topics import METADATA_NAME, PARAMETER_CHANGE_NAME, ROOT_FRAME  # noqa: F401
from flexure_sim.node.publish.interface import value_text
from flexure_sim.node.record.process import ProcessRecording, RecorderProcess

#: Suffixes tried before giving up (a directory holding that many runs of one second).
MAX_SUFFIX = 10_000


def node_token(fully_qualified_name: str) -> str:
    """
    Return the node's namespace and name as one file-name part.

    ``/left/stage_node`` becomes ``left_stage_node``.
    """
    parts = [p for p in fully_qualified_name.split("/") if p]
    return "_".join(parts) or "stage_node"


def recording_layout(record_format: str, record_path: str) -> str:
    """
    ``bag`` (a rosbag2 bag directory) or ``mcap`` (one file) for these parameters.

    A ``record_path`` ending in ``.mcap`` is one file whatever ``record_format`` says.
    """
    if record_path.endswith(".mcap"):
        return "mcap"
    return record_format


def _candidates(record_dir: str, record_path: str, mechanism_name: str, node: str, index: int,
                now: Optional[_dt.datetime], layout: str = "mcap") -> Iterator[Path]:
    if record_path:
        base = Path(record_path)
        suffix = "" if layout == "bag" else (base.suffix or ".mcap")
        if index == 0:
            yield base
        for k in range(max(index, 1), MAX_SUFFIX):
            yield base.with_name(f"{base.stem}_{k}{suffix}")
        return
    stamp = (now or _dt.datetime.now(_dt.timezone.utc)).strftime("%Y%m%dT%H%M%S")
    stem = f"{mechanism_name}_{node}_{stamp}" if node else f"{mechanism_name}_{stamp}"
    directory = Path(record_dir)
    suffix = "" if layout == "bag" else ".mcap"
    yield directory / f"{stem}{suffix}"
    for k in range(1, MAX_SUFFIX):
        yield directory / f"{stem}_{k}{suffix}"


def claim_recording_path(
    record_dir: str,
    record_path: str,
    mechanism_name: str,
    index: int,
    now: Optional[_dt.datetime] = None,
    node: str = "",
    layout: str = "mcap",
) -> Path:
    """
    Claim the first free name for the ``index``-th recording of this node (0 first).

    Create the (empty) file with ``O_EXCL``, so no other process can take it, and return its path.
    The recorder then writes into it. Creates the directory if missing; raises OSError if it cannot
    be written.

    ``record_path`` set: that file for index 0, then ``<stem>_<index><suffix>`` (the next
    free suffix if taken). Otherwise ``<record_dir>/<mechanism>_<node>_<UTC
    YYYYmmddTHHMMSS>.mcap`` (``_1``, ``_2``... appended if the name is taken), ``node`` being
    `node_token` of the node's fully qualified name. Relative paths are relative to the
    working directory.

    ``layout`` ``bag``: the same names without ``.mcap``, claimed as empty directories
    (``mkdir``, atomic too) for a rosbag2 bag directory.
    """
    parent_made = False
    for candidate in _candidates(record_dir, record_path, mechanism_name, node, index, now,
                                 layout):
        if not parent_made:
            candidate.parent.mkdir(parents=True, exist_ok=True)
            parent_made = True
        try:
            if layout == "bag":
                candidate.mkdir()
                return candidate
            fd = os.open(candidate, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            continue
        os.close(fd)
        return candidate
    raise FileExistsError(
        f"{record_dir or record_path}: {MAX_SUFFIX} recordings of one name exist")


def release_claim(path: Path) -> None:
    """Remove a claimed name that was never written (the file or directory is still empty)."""
    try:
        if path.is_dir():
            path.rmdir()  # only if empty
        elif path.stat().st_size == 0:
            path.unlink()
    except OSError:
        pass


def run_metadata(values: Mapping[str, Any], mechanism: Mechanism, mechanism_path: Path,
                 interface: Any, node: str, steps_per_tick: int, relinearize_tol: Any, run: int,
                 sim_time: float) -> dict[str, str]:
    """
    Return the ``flexure_sim`` metadata record of one recording.

    Every parameter by name, the mechanism (its YAML text included) and the engine settings.
    """
    try:
        yaml_text = mechanism_path.read_text()
    except (OSError, UnicodeDecodeError):
        yaml_text = ""
    meta = {name: value_text(value) for name, value in values.items()}
    meta.update({
        "mechanism_name": mechanism.name,
        "mechanism_path": str(mechanism_path),
        "mechanism_yaml": yaml_text,
        "node": node,
        "flexure_sim_version": __version__,
        "steps_per_tick": str(steps_per_tick),
        "relinearize_tol": repr(relinearize_tol),
        "root_frame": interface.frames.root,
        "bodies": ",".join(interface.body_names),
        "hinges": ",".join(interface.hinge_names),
        "drives": ",".join(f"{d.name}:{d.kind}" for d in mechanism.drives),
        "outputs": ",".join(o.name for o in mechanism.all_outputs),
        "run": str(run),
        "sim_time_start": repr(sim_time),
        "started_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    })
    return meta


class RecordingSession:
    """
    The node's recordings, one after the other, written by one `RecorderProcess`.

    Used by the stepping thread only (and before it starts / after it ended). A write that
    fails ends the recording: the reason is kept in `error` (diagnostics ERROR) and logged.
    """

    def __init__(self, log: Any) -> None:
        self.log = log
        self.current: Optional[ProcessRecording] = None
        self._process: Optional[RecorderProcess] = None
        self._index = 0
        self.error = ""

    def start(self, values: Mapping[str, Any], mechanism_name: str, node: str,
              topics: Sequence[tuple[str, str, Any]], metadata: Mapping[str, str],
              lossless: bool = True) -> Path:
        """
        Claim the next name and open it; raises RecordingError if that is impossible.

        ``lossless``: wait for a slow recorder (fast, lockstep); False drops and counts (real
        time).
        """
        layout = recording_layout(values["record_format"], values["record_path"])
        try:
            path = claim_recording_path(values["record_dir"], values["record_path"],
                                        mechanism_name, self._index, node=node_token(node),
                                        layout=layout)
        except OSError as exc:
            raise RecordingError(f"cannot create a recording: {exc}") from exc
        try:
            if self._process is None or not self._process.alive():
                self._process = RecorderProcess()
            # Real time may drop (counted) rather than stall the paced loop; other modes wait.
            bag = None
            if layout == "bag":
                bag = {"max_bytes": int(values["record_max_bytes"]),
                       "max_duration_ns": round(float(values["record_max_duration"]) * 1e9)}
            self.current = ProcessRecording(self._process, path, topics, metadata, METADATA_NAME,
                                            claimed=True, lossless=lossless, bag=bag)
        except BaseException:
            release_claim(path)
            raise
        self._index += 1
        self.error = ""
        wanted = next(_candidates(values["record_dir"], values["record_path"], mechanism_name,
                                  node_token(node), self._index - 1, None, layout))
        if values["record_path"] and path != wanted:
            self.log.warning(f"{wanted} exists (recordings are never overwritten): "
                             f"recording to {path} instead")
        else:
            self.log.info(f"recording to {path}")
        return path

    def stop(self) -> Optional[Path]:
        """Finish the current file; its path (None if not recording)."""
        recording, self.current = self.current, None
        if recording is None:
            return None
        try:
            stats = recording.close()
        except RecordingError as exc:
            self.error = str(exc)
            self.log.error(f"recording {recording.path} could not be finished: {exc}")
            return recording.path
        dropped = stats.get("dropped", 0)  # the child's count includes the node's drops
        self.log.info(f"closed {recording.path}: {stats.get('accepted', 0)} messages"
                      + (f", {dropped} dropped" if dropped else ""))
        return recording.path

    def write(self, items: Sequence[tuple[int, bytes]], stamp: int) -> None:
        """Record one batch (channel index, CDR bytes) at log time ``stamp`` (ns)."""
        recording = self.current
        if recording is None:
            return
        try:
            recording.write_batch(items, stamp)
        except RecordingError as exc:
            self._failed(exc)

    def write_frame(self, body: bytes, channels: Sequence[int]) -> None:
        """Record one batch frame body as packed (``ProcessRecording.write_frame``)."""
        recording = self.current
        if recording is None:
            return
        try:
            recording.write_frame(body, channels)
        except RecordingError as exc:
            self._failed(exc)

    def note(self, name: str, data: Mapping[str, str]) -> None:
        """Write a metadata record in the current file (if any)."""
        if self.current is not None:
            self.current.add_metadata(name, data)

    def _failed(self, exc: BaseException) -> None:
        self.error = str(exc)
        self.log.error(f"recording stopped: {exc}")
        recording, self.current = self.current, None
        if recording is not None:
            try:
                recording.close()
            except RecordingError:
                pass

    def close(self) -> None:
        """Finish the current file and end the recorder process (idempotent)."""
        if self.current is not None:
            self.stop()
        process, self._process = self._process, None
        if process is not None:
            process.quit()
