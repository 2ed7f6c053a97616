"""What a recording accepted and dropped, per topic (`McapRecorder.stats`, `BagRecorder.stats`)."""
from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class RecordingStats:
    """Per-topic counts of messages accepted for writing and dropped on a full queue."""

    accepted: Mapping[str, int]
    dropped: Mapping[str, int]
    pending: int = 0

    @property
    def accepted_count(self) -> int:
        return sum(self.accepted.values())

    @property
    def dropped_count(self) -> int:
        return sum(self.dropped.values())


class Counters:
    """Counts shared by the producers and the writer thread, guarded by ``lock``."""

    def __init__(self) -> None:
        self.lock = threading.RLock()  # re-entrant: a signal handler may run inside write()
        self.accepted: dict[str, int] = {}
        self.dropped: dict[str, int] = {}

    def dropped_total(self) -> int:
        with self.lock:
            return sum(self.dropped.values())

    def snapshot(self, pending: int = 0,
                 written: Mapping[str, int] | None = None) -> RecordingStats:
        """
        Return the counts now, ``pending`` batches still queued.

        ``written``: messages per topic that count as accepted once written (frames,
        `McapRecorder.write_frame`), added to those accepted when queued.
        """
        with self.lock:
            accepted, dropped = dict(self.accepted), dict(self.dropped)
        for topic, n in (written or {}).items():
            accepted[topic] = accepted.get(topic, 0) + n
        return RecordingStats(accepted, dropped, pending)
