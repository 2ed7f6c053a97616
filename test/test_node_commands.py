"""
Batch intake of drive commands (issue 18.3).

One decode and one filter call per tick must give exactly what decoding and submitting the commands
one by one gives (no ROS).
"""
from __future__ import annotations

import math
import random
import struct

from flexure_sim.node.publish.cdr import parse_float64
from flexure_sim.node.inputs.command_intake import decode_float64_batch
from flexure_sim.node.inputs.command_checks import CommandFilter, CommandStatus, DriveLimits


def one_by_one(payloads):
    values, problems = [], []
    for p in payloads:
        try:
            values.append(parse_float64(p))
        except ValueError as exc:
            problems.append(str(exc))
    return values, problems


def same(a, b):
    return len(a) == len(b) and all(
        (math.isnan(x) and math.isnan(y)) or struct.pack("<d", x) == struct.pack("<d", y)
        for x, y in zip(a, b))


def random_value(rng):
    return rng.choice([rng.uniform(-1e-5, 1e-5), math.nan, math.inf, -math.inf, 0.0, -0.0,
                       rng.uniform(-1e300, 1e300), 5e-324])


def random_payload(rng):
    kind = rng.random()
    value = random_value(rng)
    if kind < 0.6:
        return b"\x00\x01\x00\x00" + struct.pack("<d", value)
    if kind < 0.7:
        return b"\x00\x00\x00\x00" + struct.pack(">d", value)  # big-endian CDR
    if kind < 0.8:
        return b"\x00\x01\x00\x03" + struct.pack("<d", value)  # options bytes set
    if kind < 0.9:
        return bytes(rng.randrange(256) for _ in range(rng.choice([0, 2, 11, 12, 13, 16])))
    return b"\x00\x01\x00\x00" + struct.pack("<d", value) + b"\x00" * rng.choice([1, 4])


def test_batch_decoding_equals_decoding_one_by_one():
    rng = random.Random(18)
    for _ in range(3000):
        n = rng.choice([1, 2, 3, 10, 100])
        if rng.random() < 0.5:  # the fast path: all plain little-endian
            payloads = [b"\x00\x01\x00\x00" + struct.pack("<d", random_value(rng))
                        for _ in range(n)]
        else:
            payloads = [random_payload(rng) for _ in range(n)]
        values, problems = decode_float64_batch(payloads)
        want_values, want_problems = one_by_one(payloads)
        assert same(values, want_values) and problems == want_problems, payloads
    # A 2-byte payload among good ones: refused with its reason, never a value.
    good = b"\x00\x01\x00\x00" + struct.pack("<d", 1e-6)
    values, problems = decode_float64_batch([good, bytes.fromhex("0001"), good])
    assert values == [1e-6, 1e-6] and len(problems) == 1 and "too short" in problems[0]


def test_submit_many_equals_submitting_one_by_one():
    rng = random.Random(3)
    for _ in range(2000):
        limits = DriveLimits(0.0, 2e-6, 0.01)
        batch, single = CommandFilter(limits), CommandFilter(limits)
        start = rng.uniform(0, 2e-6)
        batch.submit(start)
        single.submit(start)
        batch.begin_tick(1e-3)
        single.begin_tick(1e-3)
        values = [rng.choice([rng.uniform(-1e-6, 3e-6), math.nan, math.inf, -math.inf, 0.0,
                              2e-6]) for _ in range(rng.choice([0, 1, 5, 50]))]
        rejected, clamped, last_bad, last_out = batch.submit_many(values)
        statuses = [single.submit(v) for v in values]
        assert batch.counters == single.counters
        assert batch.target == single.target and batch.applied == single.applied
        assert batch.begin_tick(1e-3) == single.begin_tick(1e-3)  # same ramp bookkeeping
        assert rejected == statuses.count(CommandStatus.REJECTED)
        assert clamped == statuses.count(CommandStatus.CLAMPED)
        bad = [v for v, s in zip(values, statuses) if s is CommandStatus.REJECTED]
        out = [v for v, s in zip(values, statuses) if s is CommandStatus.CLAMPED]
        assert (math.isnan(last_bad) if not bad else same([last_bad], [bad[-1]]))
        assert (math.isnan(last_out) if not out else last_out == out[-1])
