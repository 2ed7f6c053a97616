"""Parameter validation, real-time pacing and recording names of the stage node (no ROS)."""
import datetime as dt
import math
import multiprocessing

import numpy as np
import pytest

from flexure_sim.node.stage.pacing import Pacer, PacingStats
from flexure_sim.node.params.checks import steps_per_tick, validate
from flexure_sim.node.params.table import parameter_specs
from flexure_sim.node.record.session import (
    claim_recording_path, node_token, recording_layout, release_claim)


def defaults() -> dict:
    return {s.name: s.default for s in parameter_specs((0.0, 2e-6, 0.01))}


def test_defaults_are_valid_and_give_ten_steps_per_tick():
    values = defaults()
    assert validate(values) is None
    assert values["publish_rate"] == 1000.0 and values["sim_step"] == 1e-4
    assert values["mechanism"] == "microstage" and values["time_mode"] == "realtime"
    assert (
        values["record"] is True and values["record_dir"] == "runs" and values["record_path"] == ""
    )
    assert steps_per_tick(1000.0, 1e-4) == (10, None)
    read_only = {s.name for s in parameter_specs() if s.read_only}
    assert read_only == {"mechanism", "sim_step", "time_mode", "stepping_nice",
                         "stepping_priority", "cpu_latency_us", "command_reliability",
                         "command_depth", "frame_prefix", "space"}
    assert values["command_reliability"] == "reliable"


@pytest.mark.parametrize(
    "rate, step, n",
    [
        (1000.0, 1e-4, 10),
        (200.0, 1e-4, 50),
        (10000.0, 1e-4, 1),
        (1.0, 1e-2, 100),
        (333.0, 1 / 3330, 10),
        (100.0, 1e-3, 10),
        (3.0, 1 / 3000, 1000),
    ],
)
def test_steps_per_tick(rate, step, n):
    assert steps_per_tick(rate, step) == (n, None)


@pytest.mark.parametrize("changes, word", [
    (dict(frame_prefix="/stage1/"), "leading slash"),
    (dict(frame_prefix="stage 1/"), "whitespace"),
    (dict(display_rate=-1.0), "display_rate"),
    (dict(display_scale=float("nan")), "display_scale"),
    (dict(record_format="rosbag"), "record_format"),
    (dict(record_max_bytes=-1), "record_max_bytes"),
    (dict(record_max_duration=float("inf")), "record_max_duration"),
    (dict(sim_step=3e-4), "does not divide"),
    (dict(publish_rate=20000.0, sim_step=1e-5), "publish_rate"),
    (dict(publish_rate=0.5), "publish_rate"),
    (dict(sim_step=0.0), "sim_step"),
    (dict(sim_step=0.02), "sim_step"),
    (dict(sim_step=float("nan")), "sim_step"),
    (dict(publish_rate=20000.0), "publish_rate"),
    (dict(publish_rate=1500.0), "does not divide"),
    (dict(time_mode="slow"), "time_mode"),
    (dict(stroke_min=3e-6), "stroke_min"),
    (dict(slew_rate=0.0), "slew_rate"),
    (dict(stroke_max=float("inf")), "stroke_max"),
    (dict(record_dir=""), "record_dir"),
    (dict(mechanism=" "), "mechanism"),
    (dict(wake_spin=-1e-4), "wake_spin"),
    (dict(wake_spin=float("nan")), "wake_spin"),
    (dict(stepping_nice=-21), "stepping_nice"),
    (dict(stepping_nice=2.5), "stepping_nice"),
    (dict(stepping_priority=-1), "stepping_priority"),
    (dict(stepping_priority=100), "stepping_priority"),
    (dict(stepping_priority=50, wake_spin=1e-3), "wake_spin must be at most 0.0005 s"),
    (dict(stepping_priority=50, publish_rate=4000.0, sim_step=2.5e-5),  # the default spin
     "wake_spin must be at most 0.000125 s"),
    (dict(stepping_priority=50, wake_spin=6e-4), "stepping_priority 50 (SCHED_FIFO)"),
    (dict(cpu_latency_us=-2), "cpu_latency_us"),
    (dict(cpu_latency_us=1.5), "cpu_latency_us"),
    (dict(cpu_latency_us=True), "cpu_latency_us"),
    (dict(merge_late_ticks=-1), "merge_late_ticks"),
    (dict(merge_late_ticks=2.0), "merge_late_ticks"),
    (dict(command_reliability="sometimes"), "command_reliability"),
    (dict(command_depth=0), "command_depth"),
    (dict(command_depth=1.5), "command_depth"),
])
def test_invalid_values_are_refused_with_the_reason(changes, word):
    values = {**defaults(), **changes}
    problem = validate(values)
    assert problem is not None and word in problem


def test_the_division_reason_says_what_to_do():
    problem = validate({**defaults(), "sim_step": 3e-4})
    assert "3.33333 steps" in problem and "sim_step = period / n" in problem


def test_a_real_time_stepping_thread_needs_a_spin_of_at_most_half_a_period():
    fifo = {**defaults(), "stepping_priority": 50}
    assert fifo["time_mode"] == "realtime" and fifo["publish_rate"] == 1000.0
    assert validate({**fifo, "wake_spin": 1e-4}) is None
    assert validate({**fifo, "wake_spin": 5e-4}) is None  # exactly half the 1 ms period
    assert validate({**fifo, "wake_spin": 1e-3, "publish_rate": 500.0}) is None  # of 2 ms
    assert validate({**fifo, "time_mode": "fast"}) is None  # real time only
    assert validate({**fifo, "time_mode": "lockstep"}) is None


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t

    def sleep(self, s):
        self.t += s + 20e-6  # every sleep overshoots by 20 us


def test_pacer_uses_absolute_deadlines_so_jitter_does_not_accumulate():
    clock = FakeClock()
    pacer = Pacer(1e-3, clock=clock, sleep=clock.sleep)
    pacer.start()
    for k in range(1, 1001):
        deadline = pacer.wait()
        assert deadline == pytest.approx(100.0 + k * 1e-3)
        clock.t += 300e-6  # work
        assert pacer.done() is False
    assert clock.t == pytest.approx(100.0 + 1.0 + 320e-6, abs=1e-9)
    assert pacer.stats.missed == 0 and pacer.stats.ticks == 1000
    assert pacer.stats.max_late_s == pytest.approx(20e-6)
    # Every tick started 20 us late (the fake sleep's overshoot): p50 = p99 = the 21 us bin edge.
    assert pacer.stats.late_percentile(0.5) == pytest.approx(21e-6)
    assert pacer.stats.late_percentile(0.99) == pytest.approx(21e-6)
    assert sum(pacer.stats.late_histogram) == 1000


def test_lateness_percentiles_split_a_mixed_distribution_at_the_right_bins():
    stats = PacingStats()
    for _ in range(97):
        stats.observe(5.5e-6)
    stats.observe(3.0005e-3)
    stats.observe(-1e-6)  # early counts as on time
    stats.observe(1.0)  # beyond the histogram: the last bin
    assert stats.observed == 100 and stats.late_histogram.sum() == 100
    assert stats.late_percentile(0.5) == pytest.approx(6e-6)
    assert stats.late_percentile(0.98) == pytest.approx(6e-6)
    assert stats.late_percentile(0.99) == pytest.approx(3.001e-3)
    assert stats.late_percentile(1.0) == pytest.approx(20.001e-3)
    assert stats.max_late_s == 1.0
    assert PacingStats().late_percentile(0.99) == 0.0


@pytest.mark.parametrize("scale", [2e-6, 1e-4, 3e-3, 3e-2])
def test_lateness_percentiles_equal_the_order_statistics_of_the_samples(scale):
    """The bin holding the ceil(q n)-th smallest lateness, at every spread of the histogram."""
    samples = np.random.default_rng(7).exponential(scale, 4001)
    stats = PacingStats()
    for late in samples:
        stats.observe(late)
    ordered = np.sort(samples)
    qs = (0.5, 0.9, 0.99, 1.0)
    for q, got in zip(qs, stats.late_percentiles(*qs)):
        kth = ordered[math.ceil(q * len(samples)) - 1]
        assert got == pytest.approx(min(math.floor(kth / 1e-6) + 1, 20_001) * 1e-6)


def test_pacer_counts_overruns_catches_up_and_slips_when_far_behind():
    clock = FakeClock()
    pacer = Pacer(1e-3, max_lag_s=0.01, clock=clock, sleep=clock.sleep)
    pacer.start()
    pacer.wait()
    clock.t += 2.5e-3  # one tick takes 2.5 periods
    assert pacer.done() is True
    t_before = clock.t
    pacer.wait()  # late: no sleep, catch up
    assert clock.t == t_before
    clock.t += 1e-4
    pacer.done()
    pacer.wait()
    clock.t += 1e-4
    assert pacer.done() is False  # back on schedule after catching up
    # Tick 1 overran; tick 2, started late, also finished after tick 3 was due.
    assert pacer.stats.missed == 2 and pacer.stats.slips == 0
    clock.t += 0.05  # a 50 ms stall: more than max_lag
    pacer.wait()
    assert pacer.stats.slips == 1 and pacer.stats.skipped >= 45
    clock.t += 1e-4
    assert pacer.done() is False  # re-anchored


def test_pacer_merges_the_ticks_it_is_late_for_into_one_that_covers_their_periods():
    clock = FakeClock()
    pacer = Pacer(1e-3, merge_after=2, max_lag_s=1.0, clock=clock, sleep=clock.sleep)
    pacer.start()
    pacer.wait()
    assert pacer.span == 1
    clock.t += 1e-4
    assert pacer.done() is False
    clock.t += 5.5e-3  # a stall: tick 2 (due at 100.002) could only start at ~100.00662
    deadline = pacer.wait()
    # 4.62 periods late: ticks 2..5 are merged into tick 6, whose slot (100.006) is due now.
    assert pacer.span == 5
    assert deadline == pytest.approx(100.006)
    clock.t += 1e-4
    assert pacer.done() is False  # the merged tick itself is on time
    stats = pacer.stats
    assert (stats.merged, stats.missed, stats.ticks, stats.slips) == (4, 4, 6, 0)
    assert stats.max_late_s == pytest.approx(4.62e-3)  # how late the loop was
    # Back on the grid: one period per tick, simulated periods equal to wall time.
    assert pacer.wait() == pytest.approx(100.007) and pacer.span == 1
    clock.t += 1.5e-3  # this tick overran by half a period: less than merge_after late
    assert pacer.done() is True
    assert pacer.wait() == pytest.approx(100.008) and pacer.span == 1  # caught up tick by tick
    clock.t += 1e-4
    assert pacer.done() is False
    assert (stats.merged, stats.missed, stats.ticks) == (4, 5, 8)


def test_pacer_period_change_and_reanchor():
    clock = FakeClock()
    pacer = Pacer(1e-3, clock=clock, sleep=clock.sleep)
    pacer.start()
    pacer.wait()
    pacer.set_period(5e-3)
    d = pacer.wait()
    assert d == pytest.approx(100.0 + 1e-3 + 5e-3)
    clock.t += 1.0  # a pause (e.g. reset)
    pacer.reanchor()
    t = clock.t
    assert pacer.wait() == pytest.approx(t + 5e-3)  # one period after the pause, no catch-up
    assert pacer.stats.slips == 0
    with pytest.raises(ValueError):
        Pacer(0.0)


class TickingClock(FakeClock):
    """A FakeClock that also moves 1 us at every reading (a busy-wait's time passes)."""

    def __init__(self):
        super().__init__()
        self.sleeps: list[float] = []

    def __call__(self):
        self.t += 1e-6
        return self.t

    def sleep(self, s):
        self.sleeps.append(s)
        super().sleep(s)


def test_a_wait_with_a_spin_sleeps_only_when_the_sleep_outlasts_the_timer_slack():
    # Linux's default timer slack, 50 us (prctl(2), PR_SET_TIMERSLACK), bounds the shortest
    # sleep worth making before a busy-wait of 0.2 ms.
    spin = 2e-4
    for work, slept in ((1e-3 - spin - 30e-6, False), (1e-3 - spin - 80e-6, True)):
        clock = TickingClock()
        pacer = Pacer(1e-3, spin_s=spin, clock=clock, sleep=clock.sleep)
        pacer.start()
        start = clock.t
        clock.t += work  # the previous tick's work, 30 or 80 us before the spin would begin
        deadline = pacer.wait()
        assert deadline == pytest.approx(start + 1e-3, abs=2e-6)
        assert clock.t >= deadline  # never early, spun or slept
        assert bool(clock.sleeps) is slept, clock.sleeps
        if slept:
            assert clock.sleeps[0] == pytest.approx(80e-6, abs=3e-6)
    # Without a spin every wait sleeps, however short.
    clock = TickingClock()
    pacer = Pacer(1e-3, clock=clock, sleep=clock.sleep)
    pacer.start()
    clock.t += 1e-3 - 10e-6
    pacer.wait()
    assert len(clock.sleeps) == 1 and clock.sleeps[0] == pytest.approx(10e-6, abs=3e-6)


def test_recording_names_hold_the_node_and_take_the_next_suffix_when_taken(tmp_path):
    now = dt.datetime(2026, 1, 2, 3, 4, 5, tzinfo=dt.timezone.utc)
    d = str(tmp_path / "runs")
    first = claim_recording_path(d, "", "microstage", 0, now, node="left_stage_node")
    assert first == tmp_path / "runs" / "microstage_left_stage_node_20260102T030405.mcap"
    assert first.is_file() and first.stat().st_size == 0  # claimed
    second = claim_recording_path(d, "", "microstage", 0, now, node="left_stage_node")
    assert second.name == "microstage_left_stage_node_20260102T030405_1.mcap"
    other = claim_recording_path(d, "", "microstage", 0, now, node="right_stage_node")
    assert other.name == "microstage_right_stage_node_20260102T030405.mcap"
    assert node_token("/left/stage_node") == "left_stage_node"
    assert node_token("/stage_node") == "stage_node"
    out = tmp_path / "out" / "run.mcap"
    assert claim_recording_path("runs", str(out), "microstage", 0) == out
    assert claim_recording_path("runs", str(out), "microstage", 0).name == "run_1.mcap"
    assert claim_recording_path("runs", str(out), "microstage", 2).name == "run_2.mcap"
    assert claim_recording_path("runs", str(out), "microstage", 1).name == "run_3.mcap"
    release_claim(out)
    assert not out.exists()
    out.write_bytes(b"data")
    release_claim(out)  # never removes a file that holds anything
    assert out.read_bytes() == b"data"


def test_bag_recordings_claim_directories_and_a_dot_mcap_path_keeps_one_file(tmp_path):
    now = dt.datetime(2026, 1, 2, 3, 4, 5, tzinfo=dt.timezone.utc)
    d = str(tmp_path / "runs")
    first = claim_recording_path(d, "", "microstage", 0, now, node="stage_node", layout="bag")
    assert first == tmp_path / "runs" / "microstage_stage_node_20260102T030405"
    assert first.is_dir() and not any(first.iterdir())  # claimed, empty
    second = claim_recording_path(d, "", "microstage", 0, now, node="stage_node", layout="bag")
    assert second.name == "microstage_stage_node_20260102T030405_1" and second.is_dir()
    out = tmp_path / "out" / "run"
    assert claim_recording_path("runs", str(out), "microstage", 0, layout="bag") == out
    assert claim_recording_path("runs", str(out), "microstage", 1, layout="bag").name == "run_1"
    release_claim(out)
    assert not out.exists()
    assert recording_layout("bag", "") == "bag" and recording_layout("mcap", "") == "mcap"
    assert recording_layout("bag", "x.mcap") == "mcap" and recording_layout("bag", "x") == "bag"


def _claim_many(directory, barrier, results):
    now = dt.datetime(2026, 1, 2, 3, 4, 5, tzinfo=dt.timezone.utc)
    barrier.wait()  # all processes claim at once
    results.put([str(claim_recording_path(directory, "", "microstage", 0, now, node="stage_node"))
                 for _ in range(20)])


@pytest.mark.slow
def test_processes_racing_for_one_name_never_get_the_same(tmp_path):
    ctx = multiprocessing.get_context("spawn")
    barrier, results = ctx.Barrier(4), ctx.Queue()
    procs = [
        ctx.Process(target=_claim_many, args=(str(tmp_path), barrier, results)) for _ in range(4)
    ]
    for p in procs:
        p.start()
    names = [name for _ in procs for name in results.get(timeout=60)]
    for p in procs:
        p.join(30)
    assert len(names) == 80 and len(set(names)) == 80
    assert len(list(tmp_path.iterdir())) == 80


def test_pacer_sleeps_then_busy_waits_the_last_part():
    t = [0.0]
    slept = []

    def clock():
        t[0] += 1e-6  # every reading costs a microsecond
        return t[0]

    def sleep(s):
        slept.append(s)
        t[0] += s + 50e-6  # overshoots by 50 us

    pacer = Pacer(1e-3, spin_s=2e-4, clock=clock, sleep=sleep)
    pacer.start()
    deadline = pacer.wait()
    assert slept and slept[0] == pytest.approx(0.8e-3, abs=5e-6)  # woke 0.15 ms early, then spun
    assert deadline <= t[0] <= deadline + 5e-6


def test_numbers_given_as_integers_or_yaml_strings_set_double_parameters():
    """``ros2 param set`` reads ``2`` as an integer and ``1e-6`` as a string (YAML 1.1)."""
    from flexure_sim.node.params.table import as_declared_type

    specs = {s.name: s for s in parameter_specs((0.0, 2e-6, 0.01))}
    stroke, mode = specs["stroke_max"], specs["time_mode"]
    assert as_declared_type(stroke, "1e-6") == 1e-6 and type(as_declared_type(stroke, 2)) is float
    assert as_declared_type(stroke, "two") == "two" and as_declared_type(stroke, True) is True
    assert as_declared_type(mode, "1e-6") == "1e-6" and as_declared_type(None, 3) == 3
    # A non-finite string becomes a float that the validation then refuses, with the reason.
    values = defaults() | {"stroke_max": as_declared_type(stroke, "nan")}
    assert "stroke_max: must be finite" in validate(values)


def test_a_spinning_wait_warms_once_when_time_is_left_and_never_without_a_spin():
    clock = TickingClock()
    warmed: list[float] = []
    spin = 2e-4
    pacer = Pacer(1e-3, spin_s=spin, warm=lambda: warmed.append(clock.t), clock=clock,
                  sleep=clock.sleep)
    pacer.start()
    start = clock.t
    clock.t += 100e-6  # the previous tick's work
    deadline = pacer.wait()
    # Once, after the sleep, where the busy-wait begins (the spin's 0.2 ms before the deadline).
    assert len(warmed) == 1
    assert deadline - spin <= warmed[0] <= deadline - spin + 30e-6
    assert deadline == pytest.approx(start + 1e-3, abs=2e-6)
    # Less than pacing.WARM_MARGIN_S (50 us) left: no warm-up, the tick is due.
    clock.t = deadline + 1e-3 - 40e-6
    pacer.wait()
    assert len(warmed) == 1
    # A late tick: no wait, no warm-up.
    clock.t += 2.5e-3
    pacer.wait()
    assert len(warmed) == 1
    # Without a spin the wait sleeps to the deadline: no warm-up.
    clock = TickingClock()
    pacer = Pacer(1e-3, warm=lambda: warmed.append(clock.t), clock=clock, sleep=clock.sleep)
    pacer.start()
    pacer.wait()
    assert len(warmed) == 1
