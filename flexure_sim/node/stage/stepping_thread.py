"""
The stage node's stepping thread.

It owns the `Simulation` and the recording, and per publish tick applies the drive commands
received since the last tick (`command_intake`), advances the engine by round(1 /
(publish_rate * sim_step)) steps, reports the state in one compiled call (the engine's
``tick_report``), packs every message into one recorder frame in another (`tick_frame`),
records that frame and publishes slices of it to the subscribed topics (`raw_publish`). A
mechanism in space is reported by its snapshot and packed by its interface (`LoopParts.report`:
``spatial_report``). Built from its parts (`LoopParts`, made by ``shell.StageNode``) and its
settings (`LoopSettings`, the node's parameters).

Real-time mode paces ticks with absolute deadlines of a steady clock (`pacing.Pacer`, whose
busy-wait before a tick runs the engine's discarded next step, ``Simulation.warm``; with
``merge_late_ticks`` a loop that many ticks late merges them into one that steps the engine
through all their periods and publishes once); fast mode runs flat out; lockstep mode runs
one tick per ``~/step`` request. Between ticks the thread runs the work services and
parameter changes queued for it (`requests`). A tick whose engine step fails holds the last
good state (`engine_guard.EngineHold`): input never stops the thread.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Optional

from flexure_sim.engine.actuators.sensor import Sensor
from flexure_sim.engine.solver.simulation import SolverError
from flexure_sim.engine.solver.tick_report import TickReport
from flexure_sim.node.params.checks import monitor_every, steps_per_tick
from flexure_sim.node.publish import tick_frame
from flexure_sim.node.publish.diagnostics import Diagnostics
from flexure_sim.node.publish.display import display_every
from flexure_sim.node.publish.raw_publish import TickPublishers
from flexure_sim.node.stage.cpu_latency import request_cpu_latency
from flexure_sim.node.stage.engine_guard import EngineHold
from flexure_sim.node.stage.engine_steps import advance
from flexure_sim.node.stage.loop_parts import LoopParts
from flexure_sim.node.stage.overrun import OverrunWatch
from flexure_sim.node.stage.pacing import Pacer, set_thread_fifo, set_thread_nice
from flexure_sim.node.stage.qos_watch import GRAPH_CHECK_PERIOD_S
from flexure_sim.node.stage.requests import RequestQueue
from flexure_sim.node.stage.tick_extras import TickExtras, crossed

#: Engine's relinearize_tol: None = re-linearize only when the step's iteration stops
#: contracting (answers do not depend on where it was taken): step(n) is one compiled loop.
RELINEARIZE_TOL = None
#: Diagnostics rate (Hz of simulated time), or every tick if the publish rate is lower.
DIAGNOSTICS_RATE = 10.0
#: Real time: lateness (s) beyond which the schedule slips (re-anchors): catching up tick by
#: tick, and merging late ticks (``merge_late_ticks``; then only a stopped process slips).
SLIP_LAG_S = 0.1
MERGE_MAX_LAG_S = 1.0


class SteppingLoop:
    """Ticks of one simulation, built from its `LoopParts` (settings included); then `start`."""

    def __init__(self, parts: LoopParts) -> None:
        settings = parts.settings
        self.sim = sim = parts.sim
        self.filter = parts.filter
        self.interface = interface = parts.interface
        #: The tick topics' publish calls (raw while the thread holds them, `raw_publish`).
        self.publish_calls = TickPublishers(parts.publishers, interface.control_indices)
        self.session = parts.session
        self._log = parts.log
        self.intake = parts.intake
        self.display = parts.display
        self.graph_check = parts.graph_check
        self.throttle = parts.throttle
        time_mode, rate, dt = settings.time_mode, settings.rate, settings.dt
        self.time_mode, self.rate, self.dt = time_mode, rate, dt
        self.n_steps, _ = steps_per_tick(rate, dt)
        self.diag_every = max(1, round(rate / DIAGNOSTICS_RATE))
        self.monitor_rate = settings.monitor_rate
        #: Ticks per publication of the monitoring topics (``monitor_rate``).
        self.monitor_every = monitor_every(rate, settings.monitor_rate)
        #: Publish ticks per display tick (0: off).
        self.display_every = (display_every(rate, settings.display_rate)
                              if parts.display is not None else 0)
        #: True: a mechanism in space, reported by its snapshot (`LoopParts.report`).
        self.spatial = parts.report is not None
        #: What each tick publishes, in one compiled call (engine), and its messages packed in
        #: another (`tick_frame`; None: `interface.encode` from a snapshot, where the packed
        #: layouts do not apply).
        self.report = parts.report if self.spatial else TickReport(sim.model)
        self.reported = False
        self.frame = (tick_frame.TickFrame(interface, self.report.index)
                      if interface.packed and tick_frame.APPLIES and not self.spatial else None)
        self._output_at = self.report.index["outputs"].start
        self._data = None if self.spatial else sim.data
        self.report.fill_data(self._data)  # loads the compiled kernels before the first tick
        if self.frame is not None:
            self.frame.pack(self.report.values, 0.0, 0)
        #: The output's sensor (``output/measured``), sampled once per published tick.
        spec = interface.mechanism.sensor if interface.has_sensor else None
        self.sensor: Optional[Sensor] = Sensor(spec, 1.0 / rate) if spec is not None else None
        self.pacer: Optional[Pacer] = (
            Pacer(1.0 / rate, spin_s=min(settings.wake_spin, 1.0 / rate),
                  warm=getattr(sim, "warm", None))
            if time_mode == "realtime" else None)
        self._set_merge(settings.merge_after)
        #: Warns when real-time ticks do not fit their period (`overrun`).
        self.overrun = OverrunWatch(1.0 / rate, time.perf_counter())
        #: Niceness asked for the stepping thread (and the middleware's threads, `shell`), and
        #: the one in effect; middleware threads given it (`StageNode.adopt_middleware_threads`).
        self.nice_request = settings.nice
        self.nice = 0
        self.middleware_threads = 0
        #: SCHED_FIFO priority asked for the stepping thread in real time (0: none), and the
        #: one in effect.
        self._priority_request = settings.priority if time_mode == "realtime" else 0
        self.priority = 0
        #: CPU wake-up latency to ask for in real-time mode (`cpu_latency`; -1: none), and
        #: the one in effect while the loop runs (-1: none held).
        self._latency_request = settings.cpu_latency_us if time_mode == "realtime" else -1
        self.cpu_latency_us = -1
        self.ticks = 0
        self.runs = 0
        #: Wall time of the last tick's work (s).
        self._tick_work = 0.0
        self.hold = EngineHold()
        self._next_graph_check = 0.0
        self.requests = RequestQueue(self.alive)
        self.run_wall0 = time.perf_counter()
        self.run_sim0 = sim.state.t
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        #: Why the thread ended, if it failed.
        self.failure: Optional[BaseException] = None
        self.diagnostics: Optional[Diagnostics] = (
            Diagnostics(self, parts.diagnostics) if parts.diagnostics is not None else None)
        #: The display and diagnostics a tick made due (sent after it, `tick_extras`).
        self.extras = TickExtras(self)

    # ------------------------------------------------------------------ thread
    def start(self, on_end: Any, on_failure: Any, on_running: Any = None) -> None:
        """
        Run the loop in its own thread.

        ``on_running()`` is called once, just before the first tick (the node's ``~/ready``);
        ``on_end(ok)`` when it ends; ``on_failure(exc)`` first if it raised: it reports
        and returns whether that is a failure (False: the node was shutting down anyway).
        """
        self._on_end, self._on_failure = on_end, on_failure
        self._on_running = on_running
        self._thread = threading.Thread(target=self._run, name="stage-stepping", daemon=True)
        self._thread.start()

    def alive(self) -> bool:
        thread = self._thread
        return thread is not None and thread.is_alive()

    def stop(self, timeout: float) -> None:
        """End the thread (waits up to ``timeout`` s); idempotent."""
        self._stop.set()
        self.requests.wake.set()
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=timeout)

    def _run(self) -> None:
        latency = None
        try:
            self.nice, refused = set_thread_nice(self.nice_request)
            if refused:
                self._log.info(f"stepping thread: {refused}")
            if self._priority_request:
                self.priority, refused = set_thread_fifo(self._priority_request)
                if refused:
                    self._log.info(f"stepping thread: {refused}")
            if self._latency_request >= 0:
                latency, refused = request_cpu_latency(self._latency_request)
                if latency is None:
                    self._log.info(f"stepping thread: {refused}")
                else:
                    self.cpu_latency_us = latency.latency_us
            pacer = self.pacer
            if pacer is not None:
                pacer.start()
            self.restart_clocks()
            if self._on_running is not None:
                self._on_running()
            with self.publish_calls.hold():
                self._ticks(pacer)
        except BaseException as exc:  # noqa: BLE001 - reported, then the node shuts down
            if not self._stop.is_set() and self._on_failure(exc):
                self.failure = exc
        finally:
            if self.diagnostics is not None:  # however the ticks ended (``publish_final``)
                self.diagnostics.publish_final(round(self.sim.state.t * 1e9), self._log)
            if latency is not None:
                latency.release()
                self.cpu_latency_us = -1
            self.requests.fail_all()
            self._on_end(self.failure is None)

    def _ticks(self, pacer: Optional[Pacer]) -> None:
        """Serve requests and run ticks (paced in real time) until `stop`."""
        requests = self.requests
        while not self._stop.is_set():
            if requests and requests.serve() and pacer is not None:
                pacer.reanchor()
            if self.time_mode == "lockstep":
                requests.wake.wait(0.1)
                requests.wake.clear()
                self._check_graph()
                continue
            if pacer is None:
                self.tick()
            else:
                pacer.wait()
                self.tick(defer=True)
                missed = pacer.done()
                self.extras.send(pacer.next_deadline, pacer.clock)
                warning = self.overrun.tick(time.perf_counter(), self._tick_work, missed,
                                            self._settings_text())
                if warning is not None:
                    self._log.warning(warning)
            self._check_graph()
        self.extras.send()  # what still waits goes out before the final status

    def _check_graph(self) -> None:
        """Run `graph_check` if it is due (after a tick's work: it never delays one)."""
        check = self.graph_check
        if check is not None:
            now = time.monotonic()
            if now >= self._next_graph_check:
                self._next_graph_check = now + GRAPH_CHECK_PERIOD_S
                check()

    def restart_clocks(self) -> None:
        """Start a new run or window now (wall clock and simulated time)."""
        if self.diagnostics is not None:
            self.diagnostics.window = self.diagnostics.new_window()
        self.run_wall0, self.run_sim0 = time.perf_counter(), self.sim.state.t

    # ------------------------------------------------------------------ ticks
    def step_once(self) -> tuple[bool, str]:
        """One tick (lockstep ``~/step``) to the topics subscribed at the call."""
        self.publish_calls.refresh()
        if not self.tick():
            return False, f"{self.hold.last_error}; state held at t = {self.sim.state.t:.9g} s"
        return True, f"t = {self.sim.state.t:.9g} s"

    def _advance_engine(self) -> None:
        """Take the tick's engine steps, following the drive filter's ramp (`engine_steps`)."""
        advance(self.sim, self.filter, self.intake, self.n_steps, self.dt)

    def _merged_periods(self, count: int) -> None:
        """
        Step through ``count`` tick periods that are not published (merged ticks, real time).

        The sensor still samples each (its noise sequence and latency count ticks).
        """
        sim, sensor = self.sim, self.sensor
        for _ in range(count):
            self._advance_engine()
            if sensor is not None:
                sensor.sample(float(sim.model.output_displacement(sim.state.z)))

    def tick(self, defer: bool = False) -> bool:
        """
        One publish tick: commands, engine steps, report, pack, record, publish.

        In real time it may cover several periods (`Pacer.span`): the engine steps through
        all of them, the state at the end is published. Returns False when the engine failed:
        the state is then held and only diagnostics go out. ``defer``: the display and
        diagnostics it makes due wait in `extras` (sent by the paced loop, `tick_extras`).
        """
        perf = time.perf_counter
        t0 = perf()
        sim = self.sim
        span = self.pacer.span if self.pacer is not None else 1
        if self.intake is not None:
            self.intake.apply(round(sim.state.t * 1e9))
        self.hold.save(sim, self.filter)
        t1 = perf()
        report = self.report
        try:
            if span > 1:
                self._merged_periods(span - 1)
            self._advance_engine()
            t2 = perf()
            values = report.fill_data(self._data)
            if not report.finite:
                raise SolverError(f"non-finite result at t = {sim.state.t:.9g} s")
        except Exception as exc:  # noqa: BLE001 - any engine failure: hold, report, go on
            message = self.hold.restore(sim, self.filter, exc)
            if self.throttle.event("engine") is not None:
                self._log.error(message + f" ({self.hold.failures} engine failures in all)")
            self._count_tick(span)
            self._tick_work = perf() - t0
            if not defer:
                self.extras.send()
            return False
        t3 = perf()
        self.reported = True
        stamp = round(sim.state.t * 1e9)
        measured = (self.sensor.sample(float(values[self._output_at]))
                    if self.sensor is not None else 0.0)
        monitor = crossed(self.ticks, span, self.monitor_every)
        publishers = self.publish_calls.current(monitor)
        session = self.session
        frame = self.frame
        # Recorded first, so that the file holds every message a subscriber can have seen even
        # if a shutdown interrupts the publishing. Channels 0..n-1: the tick topics.
        if frame is not None:
            body, layout = frame.pack(values, measured, stamp, monitor)
            t4 = perf()
            if session.current is not None:
                session.write_frame(body, layout.channels)
            t5 = perf()
            spans = layout.spans
            for k, publish in publishers:
                start, end = spans[k]
                publish(body[start:end])
        else:
            snap = report.last_snapshot if self.spatial else sim.snapshot()
            payloads = self.interface.encode(snap, stamp, measured, monitor)
            channels = range(len(payloads)) if monitor else self.interface.control_indices
            t4 = perf()
            if session.current is not None:
                session.write(list(zip(channels, payloads)), stamp)
            t5 = perf()
            for k, publish in publishers:
                publish(payloads[k])
        t6 = perf()
        self._tick_work = t6 - t0
        if self.diagnostics is not None:
            self.diagnostics.window.add(t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5,
                                        t6 - t0)
        self._count_tick(span, bool(self.display_every)
                         and crossed(self.ticks, span, self.display_every))
        if not defer:
            self.extras.send()
        return True

    def _settings_text(self) -> str:
        """Return the settings the overrun warning quotes (`overrun`)."""
        return (f"publish_rate {self.rate:g} Hz, monitor_rate {self.monitor_rate:g} Hz, "
                f"stepping_priority {self.priority}")

    def _count_tick(self, span: int = 1, display: bool = False) -> None:
        """Count the tick; make its display (if ``display``) and diagnostics due (`extras`)."""
        first = self.ticks + 1
        self.ticks += span
        self.extras.note(display, crossed(first, span, self.diag_every))

    # ------------------------------------------------------------- live changes
    def _set_merge(self, merge_after: int) -> None:
        """Merge late ticks from ``merge_after`` ticks of lateness on (0: never)."""
        pacer = self.pacer
        if pacer is not None:
            pacer.merge_after = merge_after
            pacer.max_lag_s = max(MERGE_MAX_LAG_S if merge_after else SLIP_LAG_S,
                                  2.0 * pacer.period)

    def set_pacing(self, rate: float, wake_spin: float, monitor_rate: float = 0.0,
                   merge_after: int = 0) -> None:
        """Apply a new publish rate, busy-wait, monitoring rate and merging (stepping thread)."""
        self.monitor_rate = monitor_rate
        self.monitor_every = monitor_every(rate, monitor_rate)
        if self.pacer is not None:
            self.pacer.spin_s = min(wake_spin, 1.0 / rate)
        if rate == self.rate:
            self._set_merge(merge_after)
            return
        self.rate = rate
        self.n_steps, _ = steps_per_tick(rate, self.dt)
        self.diag_every = max(1, round(rate / DIAGNOSTICS_RATE))
        if self.sensor is not None:
            self.sensor.set_period(1.0 / rate)
        if self.pacer is not None:
            self.pacer.set_period(1.0 / rate)
        self.overrun.set_period(1.0 / rate, time.perf_counter())
        self._set_merge(merge_after)
        self._log.info(f"publish_rate {rate:g} Hz: {self.n_steps} engine steps per tick")

    def reset(self) -> None:
        """
        Back to t = 0 and the initial command (stepping thread).

        The run's counters (ticks, the pacer's missed/paced ticks, slips, lateness) restart;
        the command and engine counters count over the node's life.
        """
        self.sim.reset()
        if self.sensor is not None:
            self.sensor.reset()
        if self.filter is not None:
            self.filter.reset()
            if self.filter.differs(0.0):
                self.sim.set_command(self.filter.applied)
        if self.intake is not None:
            self.intake.discard()  # sent before the reset: discarded
        self.runs += 1
        self.ticks = 0
        if self.pacer is not None:
            self.pacer.reset_stats()
        self.restart_clocks()
