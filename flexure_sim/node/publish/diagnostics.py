"""
The stage node's ``diagnostics`` topic.

One ``DiagnosticStatus`` per window of ticks (~10 Hz of simulated time) with timings, pacing,
solver work, command counters, engine failures, recording state, QoS problems and the largest hinge
stress ratio, at level OK, WARN or ERROR (docs/node.md).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Generator

from flexure_sim.node.publish import interface as itf


#: The parts of a tick timed by the stepping loop, in order (`Window.add`): commands taken and
#: the state saved, engine steps, tick report, packing, hand-off to the recorder, publishing.
TICK_PARTS = ("intake", "engine", "report", "pack", "record", "publish")


class Window:
    """
    Accumulators of one diagnostics window and the cumulative counters at its start.

    The accumulators are wall-clock timings of the stepping thread: per part of a tick
    (`TICK_PARTS`) its sum, and the largest engine, publishing and whole-tick times.
    """

    __slots__ = ("ticks", "sums", "engine_max", "publish_max", "tick_sum", "tick_max",
                 "wall0", "sim0", "missed0", "lin0", "steps0", "counters0", "engine_failures0",
                 "intake0")

    def __init__(self, wall0: float, sim0: float, missed0: int, lin0: int, steps0: int,
                 counters0: dict[str, int], engine_failures0: int,
                 intake0: tuple[int, float]) -> None:
        self.ticks = 0
        self.sums = [0.0] * len(TICK_PARTS)
        self.engine_max = self.publish_max = self.tick_sum = self.tick_max = 0.0
        self.wall0, self.sim0, self.missed0 = wall0, sim0, missed0
        self.lin0, self.steps0 = lin0, steps0
        self.counters0 = counters0
        self.engine_failures0 = engine_failures0
        self.intake0 = intake0

    def add(self, intake: float, engine: float, report: float, pack: float, record: float,
            publish: float, tick: float) -> None:
        """One tick's wall-clock times (s): each part of `TICK_PARTS`, and the whole tick."""
        self.ticks += 1
        sums = self.sums
        sums[0] += intake
        sums[1] += engine
        sums[2] += report
        sums[3] += pack
        sums[4] += record
        sums[5] += publish
        self.tick_sum += tick
        if engine > self.engine_max:
            self.engine_max = engine
        if publish > self.publish_max:
            self.publish_max = publish
        if tick > self.tick_max:
            self.tick_max = tick


@dataclass(frozen=True)
class DiagnosticsPort:
    """
    Where the diagnostics go.

    ``publisher``, recording ``channel``, the status' ``name`` and ``hardware_id``; ``extra``
    returns further (values, notes, level) from the node (QoS problems).
    """

    publisher: Any
    channel: int
    name: str
    hardware_id: str
    extra: Any = None


class Diagnostics:
    """
    Builds and publishes the status of the stepping loop ``loop`` (a `SteppingLoop`).

    Recorded on the port's channel of the loop's recording session, then published by its
    publisher (`DiagnosticsPort`).
    """

    def __init__(self, loop: Any, port: DiagnosticsPort) -> None:
        self.loop = loop
        self._publisher = port.publisher
        self._channel = port.channel
        self._name = port.name
        self._hardware_id = port.hardware_id
        self._extra = port.extra
        hinges = loop.sim.mechanism.hinges
        #: The hinges with a yield strength (indices, names): their stress ratios are in the
        #: tick report.
        self._stress = [(k, h.name) for k, h in enumerate(hinges)
                        if getattr(h, "stress", None) is not None
                        and h.stress.sigma_y is not None]  # no stress data in 3-D
        self.window = self.new_window()

    def stress_ratio(self) -> tuple[list[tuple[str, Any]], list[str], int]:
        """
        (values, notes, level).

        The largest hinge stress ratio sigma / sigma_y at the window's last tick
        (engine/hinges/stress.py), WARN above 1; nothing if no hinge has sigma_y.
        """
        report = self.loop.report
        if not self._stress or not self.loop.reported:
            return [], [], itf.OK
        ratios = report.values[report.index["stress_ratios"]]
        k, name = max(self._stress, key=lambda hinge: ratios[hinge[0]])  # the first largest
        ratio = float(ratios[k])
        values = [("stress_ratio_max", ratio), ("stress_ratio_hinge", name)]
        if ratio > 1.0:
            return values, [f"hinge {name} above its yield strength "
                            f"(stress ratio {ratio:.3g})"], itf.WARN
        return values, [], itf.OK

    def counters(self) -> dict[str, int]:
        filt = self.loop.filter
        return filt.counters.as_dict() if filt is not None else {}

    def intake(self) -> tuple[int, float]:
        """Commands taken so far and the time their intake took (s)."""
        intake = self.loop.intake
        return (intake.count, intake.time_s) if intake is not None else (0, 0.0)

    def new_window(self) -> Window:
        loop = self.loop
        pacer = loop.pacer
        stats = loop.sim.stats
        return Window(time.perf_counter(), loop.sim.state.t, pacer.stats.missed if pacer else 0,
                      stats.linearizations, stats.steps, self.counters(), loop.hold.failures,
                      self.intake())

    def publish_final(self, stamp: int, log: Any) -> None:
        """
        Send, at the stop, the status of the ticks since the last one (none if there were none).

        Recorded, so that the recording's last status holds the run's final counters
        (``analyse``), and published if ROS still can: a stop by a signal has usually shut
        rclpy's context down by then, and may have ended the ticks with rclpy's error. It never
        raises (the stepping thread's clean-up goes on): a status it cannot make goes to
        ``log`` as an error.
        """
        if not self.window.ticks:
            return
        try:
            payload = self.record(stamp)
        except Exception as exc:  # noqa: BLE001 - see the docstring
            log.error(f"the status at the stop is not recorded: {exc!r}")
            return
        try:
            self._publisher.publish(payload)
        except Exception:  # noqa: BLE001 - rclpy's context already shut down: recorded anyway
            pass

    def publish(self, stamp: int) -> None:
        """Publish (and record) the status of the window ending now; start a new window."""
        for _ in self.stages(stamp):
            pass

    def record(self, stamp: int) -> bytes:
        """Record the status of the window ending now and return it (CDR); start a new window."""
        stages = self.stages(stamp, publish=False)
        while True:
            try:
                next(stages)
            except StopIteration as end:
                return end.value

    def stages(self, stamp: int, publish: bool = True) -> Generator[None, None, bytes]:
        """
        `publish` in stages, yielding between them (the paced loop's slack, `tick_extras`).

        The window's values (and a new window), their text, its packing, the recording, the
        publishing (unless not ``publish``); returns the status (CDR).
        """
        level, message, values = self._status()
        yield
        values = [(key, itf.value_text(value)) for key, value in values]
        yield
        payload = itf.encode_diagnostics(
            stamp, f"{self._name}: simulation", self._hardware_id, level, message, values)
        yield
        self.loop.session.write(((self._channel, payload),), stamp)
        if publish:
            yield
            self._publisher.publish(payload)
        return payload

    def _status(self) -> tuple[int, str, list[tuple[str, Any]]]:
        """(level, message, values) of the window ending now; start a new window."""
        loop = self.loop
        w = self.window
        now = time.perf_counter()
        t = loop.sim.state.t
        wall = now - w.wall0
        rtf = (t - w.sim0) / wall if wall > 0 else 0.0
        n = max(w.ticks, 1)
        pacer = loop.pacer
        counters = self.counters()
        new = {k: counters[k] - w.counters0.get(k, 0) for k in counters}
        stats = loop.sim.stats
        steps = stats.steps - w.steps0
        level, notes = itf.OK, []
        missed_window = (pacer.stats.missed - w.missed0) if pacer else 0
        if missed_window:
            level, notes = itf.WARN, notes + [f"{missed_window} missed ticks"]
        if new.get("rejected"):
            level, notes = itf.WARN, notes + [f"{new['rejected']} commands rejected"]
        if new.get("clamped"):
            level, notes = itf.WARN, notes + [f"{new['clamped']} commands clamped"]
        lost = sum(v for k, v in new.items() if k == "lost" or k.endswith("_lost"))
        if lost:
            level, notes = itf.WARN, notes + [f"{lost} commands lost before a tick took them"]
        if new.get("rate_limited"):
            notes.append(f"{new['rate_limited']} commands rate-limited")
        extra_values: list[tuple[str, Any]] = []
        if self._extra is not None:
            extra_values, extra_notes, extra_level = self._extra()
            notes += extra_notes
            level = max(level, extra_level)
        stress_values, stress_notes, stress_level = self.stress_ratio()
        notes += stress_notes
        level = max(level, stress_level)
        hold = loop.hold
        failures = hold.failures - w.engine_failures0
        if failures:
            level, notes = itf.ERROR, notes + [
                f"{failures} engine failures, state held: {hold.last_error}"]
        session = loop.session
        rec = session.current
        if session.error:
            level, notes = itf.ERROR, notes + [f"recording failed: {session.error}"]
        elif rec is not None and rec.dropped_count:
            level, notes = max(level, itf.WARN), notes + [
                f"{rec.dropped_count} messages not recorded"]
        values: list[tuple[str, Any]] = [
            ("sim_time", t),
            ("time_mode", loop.time_mode),
            ("real_time_factor", rtf),
            ("real_time_factor_run", (t - loop.run_sim0) / max(now - loop.run_wall0, 1e-9)),
            ("publish_rate", loop.rate),
            ("sim_step", loop.dt),
            ("steps_per_tick", loop.n_steps),
            ("stepping_nice", loop.nice),
            ("middleware_threads", loop.middleware_threads),
            ("stepping_priority", loop.priority),
            ("cpu_latency_us", loop.cpu_latency_us),
            ("ticks", loop.ticks),
            ("subscribed_topics", loop.publish_calls.subscribed_count),
            *[(f"{part}_time_mean_us", 1e6 * total / n)
              for part, total in zip(TICK_PARTS, w.sums)],
            ("engine_time_max_us", 1e6 * w.engine_max),
            ("engine_step_time_mean_us", 1e6 * w.sums[1] / max(steps, 1)),
            ("publish_time_max_us", 1e6 * w.publish_max),
            ("tick_time_mean_us", 1e6 * w.tick_sum / n),
            ("tick_time_max_us", 1e6 * w.tick_max),
            ("solver_iterations", getattr(stats, "iterations", 0)),
            ("linearizations", stats.linearizations),
            ("linearizations_window", stats.linearizations - w.lin0),
            ("engine_steps", stats.steps),
            ("engine_failures", hold.failures),
            ("engine_error", hold.last_error),
        ]
        if pacer is not None:
            p50, p99 = pacer.stats.late_percentiles(0.5, 0.99)
            values += [
                ("missed_ticks", pacer.stats.missed),
                ("missed_ticks_window", missed_window),
                ("paced_ticks", pacer.stats.ticks),
                ("slips", pacer.stats.slips),
                ("skipped_ticks", pacer.stats.skipped),
                ("merged_ticks", pacer.stats.merged),
                ("max_late_us", 1e6 * pacer.stats.max_late_s),
                ("wake_spin_us", 1e6 * pacer.spin_s),
                ("jitter_p50_us", 1e6 * p50),
                ("jitter_p99_us", 1e6 * p99),
            ]
        values += [(f"commands_{k}", v) for k, v in counters.items()]
        taken, intake_s = self.intake()
        taken -= w.intake0[0]
        values.append(("command_time_mean_us",
                       1e6 * (intake_s - w.intake0[1]) / taken if taken else 0.0))
        if loop.filter is not None:
            values += loop.filter.values()
        values += extra_values + stress_values
        if loop.display is not None:
            values += loop.display.values()
        extras = getattr(loop, "extras", None)
        if extras is not None:
            values += extras.values()
        values += [
            ("recording", rec is not None),
            ("recording_path", str(rec.path) if rec is not None else ""),
            ("recorded_messages", rec.accepted_count if rec is not None else 0),
            ("recording_dropped", rec.dropped_count if rec is not None else 0),
        ]
        self.window = self.new_window()
        return level, "; ".join(notes) if notes else "running", values
