"""
The display and diagnostics of a paced tick go out after its deadline is checked (`tick_extras`).

A real stepping loop of the stage (real `Simulation`, `StageInterface`, `Display`,
`Diagnostics`, recording session) is paced by a `Pacer` on a clock the test keeps: the loop's
work takes no time on it except the display, which is made to take 1.5 periods (or a part of a
period in each of its stages). Published inside the tick, every display tick would end after
the next tick was due; sent after the deadline check, no tick misses and the display's time
shows as the next tick's late start; sent in stages within the slack, no tick starts late.
"""
from __future__ import annotations

import pytest

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.node.publish.diagnostics import DiagnosticsPort
from flexure_sim.node.publish.display import Display, DisplayOutput
from flexure_sim.node.publish.interface import StageInterface
from flexure_sim.node.record.session import RecordingSession
from flexure_sim.node.stage.loop_parts import LoopParts, LoopSettings
from flexure_sim.node.stage.pacing import Pacer
from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL, SteppingLoop

from test_node_stepping import Log  # a logger that discards

DT = 1.0e-4
RATE = 1000.0
PERIOD = 1.0 / RATE
#: Publish ticks per display tick.
DISPLAY_EVERY = 4


class Kept:
    """A publisher that keeps what it is given, in order, in a list shared by several."""

    def __init__(self, name: str, sent: list[str], then=None) -> None:
        self.name, self.sent, self.then = name, sent, then
        self.last = None

    def publish(self, data) -> None:
        self.sent.append(self.name)
        self.last = data
        if self.then is not None:
            self.then()


class ManualClock:
    """The pacer's clock: it moves only when the pacer sleeps or a publisher advances it."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds


def make_loop(sent: list[str], display_takes: float, clock: ManualClock) -> SteppingLoop:
    """Build a real-time loop at 1 kHz with markers every DISPLAY_EVERY ticks and diagnostics."""
    stage = load_mechanism("microstage")
    sim = Simulation(stage, dt=DT, relinearize_tol=RELINEARIZE_TOL)
    interface = StageInterface(stage, "realtime")
    session = RecordingSession(Log())
    n = len(interface.tick_topics)
    markers = Kept("markers", sent, lambda: clock.advance(display_takes))
    display = DisplayOutput(Display(stage, interface.frames, 1.0), markers, session, [n + 1])
    parts = LoopParts(LoopSettings("realtime", RATE, DT, display_rate=RATE / DISPLAY_EVERY),
                      sim, interface, [Kept("tick", sent) for _ in range(n)], session, Log(),
                      display=display,
                      diagnostics=DiagnosticsPort(Kept("diagnostics", sent), n, "stage", "test"))
    return SteppingLoop(parts)


def run_paced(loop: SteppingLoop, clock: ManualClock, ticks: int) -> Pacer:
    """Run the loop's own paced ticks on ``clock`` until ``ticks`` periods have passed."""
    def sleep(seconds: float) -> None:
        clock.advance(seconds)
        if clock.now >= ticks * PERIOD:
            loop.stop(0.0)

    pacer = Pacer(PERIOD, clock=clock, sleep=sleep)
    loop.pacer = pacer
    pacer.start()
    loop._ticks(pacer)
    return pacer


def test_a_display_longer_than_the_slack_makes_no_paced_tick_miss():
    sent: list[str] = []
    clock = ManualClock()
    loop = make_loop(sent, 1.5 * PERIOD, clock)
    pacer = run_paced(loop, clock, 200)
    ticks, displays = pacer.stats.ticks, sent.count("markers")
    assert ticks >= 150 and displays == ticks // DISPLAY_EVERY
    assert sent.count("diagnostics") == ticks // round(RATE / 10.0)
    # Each display pushed the next tick 0.5 periods past its deadline, within its period.
    assert pacer.stats.missed == 0
    assert pacer.stats.max_late_s == pytest.approx(0.5 * PERIOD)
    assert pacer.stats.late_percentile(1.0) >= 0.5 * PERIOD


def test_a_display_longer_than_two_periods_still_counts_the_next_tick_missed():
    sent: list[str] = []
    clock = ManualClock()
    loop = make_loop(sent, 2.5 * PERIOD, clock)
    pacer = run_paced(loop, clock, 200)
    # The next tick starts 1.5 periods late and so ends after its own successor was due; the
    # last display goes out when the loop stops, after its last tick.
    assert pacer.stats.missed == sent.count("markers") - 1 > 0
    assert loop.extras.forced > 0


def test_a_display_in_stages_goes_out_in_the_slack_of_several_ticks():
    sent: list[str] = []
    clock = ManualClock()
    loop = make_loop(sent, 0.4 * PERIOD, clock)  # its publishing: 0.4 periods
    shown = loop.display.display
    geometry, pack = shown.scene.geometry, shown.packer.pack

    def slow_geometry(*args):
        clock.advance(0.4 * PERIOD)
        return geometry(*args)

    def slow_pack(*args):
        clock.advance(0.4 * PERIOD)
        return pack(*args)

    shown.scene.geometry, shown.packer.pack = slow_geometry, slow_pack
    pacer = run_paced(loop, clock, 200)
    ticks, displays = pacer.stats.ticks, sent.count("markers")
    assert ticks >= 190 and displays == ticks // DISPLAY_EVERY
    # 1.2 periods of display in all: sent whole it would start every next tick 0.2 periods
    # late. Only the first one, whose stages' times were not known yet, went out whole.
    late = pacer.stats.observed - pacer.stats.late_histogram[0]
    assert late == 1
    assert pacer.stats.max_late_s == pytest.approx(0.2 * PERIOD)
    assert pacer.stats.missed == 0
    assert loop.extras.deferred >= displays - 1 and loop.extras.forced == 0
    # The diagnostics say so.
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message

    status = deserialize_message(loop.diagnostics._publisher.last, DiagnosticArray).status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert int(values["extras_deferred"]) > 0 and values["extras_forced"] == "0"


def test_extras_follow_the_ticks_topics_in_every_mode():
    sent: list[str] = []
    clock = ManualClock()
    loop = make_loop(sent, 0.0, clock)
    loop.tick()  # as lockstep and fast mode tick: everything at the end of the tick
    for _ in range(DISPLAY_EVERY - 1):
        loop.tick(defer=True)
        assert not loop.extras.due
    del sent[:]
    assert loop.tick(defer=True) and loop.extras.due
    assert sent and set(sent) == {"tick"}  # the tick's topics only
    loop.extras.send()
    assert sent[-1] == "markers" and not loop.extras.due
    loop.extras.send()  # nothing twice
    assert sent.count("markers") == 1
