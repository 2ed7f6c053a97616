"""Drive command validation (flexure_sim.node.inputs.command_checks), without ROS."""
import math

import pytest

from flexure_sim.node.inputs.command_checks import (
    CommandFilter,
    CommandStatus,
    DriveLimits,
    WarningThrottle,
    limits_problem,
)

STAGE = DriveLimits(0.0, 2e-6, 0.01)


def test_finite_commands_inside_the_stroke_are_accepted_unchanged():
    f = CommandFilter(STAGE)
    assert f.submit(1.35e-6) is CommandStatus.ACCEPTED
    assert f.target == 1.35e-6
    assert f.counters.as_dict() == dict(received=1, accepted=1, clamped=0, rejected=0, malformed=0,
                                        rate_limited=0, lost=0, unheard=0)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, float("nan"), "1e-6", None, True])
def test_non_finite_or_non_numeric_commands_are_rejected_and_leave_the_target(bad):
    f = CommandFilter(STAGE)
    f.submit(1e-6)
    assert f.submit(bad) is CommandStatus.REJECTED
    assert f.target == 1e-6
    assert (f.counters.received, f.counters.rejected, f.counters.accepted) == (2, 1, 1)


@pytest.mark.parametrize(
    "value, clamped", [(5e-6, 2e-6), (-1e-9, 0.0), (2e-6 + 1e-18, 2e-6), (1e300, 2e-6)]
)
def test_commands_outside_the_stroke_are_clamped_and_counted(value, clamped):
    f = CommandFilter(STAGE)
    assert f.submit(value) is CommandStatus.CLAMPED
    assert f.target == clamped
    assert (f.counters.accepted, f.counters.clamped) == (1, 1)


def test_the_stroke_ends_themselves_are_not_clamped():
    f = CommandFilter(STAGE)
    assert f.submit(2e-6) is CommandStatus.ACCEPTED and f.submit(0.0) is CommandStatus.ACCEPTED
    assert f.counters.clamped == 0


def test_slew_limit_ramps_the_applied_target_step_by_step():
    f = CommandFilter(DriveLimits(0.0, 2e-6, 1e-4))  # 0.1 um per ms
    f.submit(1e-6)
    assert f.begin_tick(period=1e-3) is True  # 1 um in 1 ms is 10x too fast
    applied = [f.advance(1e-4) for _ in range(120)]
    assert applied[0] == pytest.approx(1e-8)
    assert all(b - a <= 1e-8 * (1 + 1e-12) for a, b in zip([0.0] + applied, applied))
    assert applied[98] < 1e-6 and applied[100] == 1e-6 and f.settled
    assert f.counters.rate_limited == 1
    assert f.begin_tick(1e-3) is False  # counted once per command


def test_a_command_reachable_within_the_tick_is_not_counted_but_still_slew_limited():
    f = CommandFilter(STAGE)  # 0.01 m/s: 1 um per 0.1 ms engine step, 10 um per 1 ms tick
    f.submit(1.35e-6)
    assert f.begin_tick(1e-3) is False
    assert [f.advance(1e-4) for _ in range(3)] == pytest.approx(
        [1e-6, 1.35e-6, 1.35e-6], rel=1e-15
    )
    assert f.applied == 1.35e-6 and f.settled
    assert f.counters.rate_limited == 0


def test_only_the_last_command_of_a_tick_counts_for_the_rate_limit():
    f = CommandFilter(DriveLimits(0.0, 2e-6, 1e-4))
    for v in (2e-6, 1e-6, 5e-8):  # the first two would be too fast; the last is reachable
        f.submit(v)
    assert f.begin_tick(1e-3) is False and f.counters.rate_limited == 0
    assert f.advance(1e-3) == 5e-8


def test_ramp_reverses_when_a_new_command_arrives():
    f = CommandFilter(DriveLimits(-1.0, 1.0, 1.0))
    f.submit(1.0)
    f.advance(0.25)
    f.submit(-1.0)
    assert f.advance(0.5) == pytest.approx(-0.25)


def test_new_limits_clamp_the_current_target_and_reset_keeps_the_counters():
    f = CommandFilter(STAGE)
    f.submit(1.8e-6)
    f.advance(1.0)
    f.set_limits(DriveLimits(0.0, 1e-6, 0.01))
    assert f.target == 1e-6 and f.applied == 1.8e-6 and not f.settled
    assert f.advance(1.0) == 1e-6
    f.submit(math.nan)
    f.reset()
    assert f.target == f.applied == 0.0
    assert f.counters.received == 2 and f.counters.rejected == 1


def test_the_initial_target_lies_inside_the_stroke():
    f = CommandFilter(DriveLimits(1e-7, 2e-6, 0.01))
    assert f.target == f.applied == 1e-7


@pytest.mark.parametrize("args, word", [
    ((1e-6, 0.0, 0.01), "must not exceed"),
    ((0.0, 1e-6, 0.0), "slew_rate"),
    ((0.0, 1e-6, -1.0), "slew_rate"),
    ((math.nan, 1e-6, 0.01), "stroke_min"),
    ((0.0, math.inf, 0.01), "stroke_max"),
    ((0.0, 1e-6, "fast"), "slew_rate"),
])
def test_invalid_limits_are_refused_with_the_reason(args, word):
    problem = limits_problem(*args)
    assert problem is not None and word in problem
    with pytest.raises(ValueError, match=word):
        DriveLimits(*args)


def test_warning_throttle_emits_once_per_interval_with_the_count_it_stands_for():
    now = [0.0]
    throttle = WarningThrottle(1.0, clock=lambda: now[0])
    assert throttle.event("rejected") == 1
    for _ in range(9):
        now[0] += 0.01
        assert throttle.event("rejected") is None
    assert throttle.event("clamped") == 1  # kinds are independent
    now[0] = 1.2
    assert throttle.event("rejected") == 10  # 9 suppressed + this one
    assert throttle.event("rejected") is None


def test_malformed_payloads_are_counted_as_rejected_and_keep_the_target():
    f = CommandFilter(STAGE)
    assert f.submit(1e-6) is CommandStatus.ACCEPTED
    f.reject_malformed()
    c = f.counters.as_dict()
    assert (c["received"], c["accepted"], c["rejected"], c["malformed"]) == (2, 1, 1, 1)
    assert f.target == 1e-6
