"""
Requests too large to hold, run under an address-space limit as a user's shell would set it.

Each command runs as a subprocess with ``RLIMIT_AS`` at 2 GiB (``ulimit -v``; a sweep of a
small study peaks below 1.5 GiB): a study of 10^15 designs, a ``range`` of 10^9 values, a
10^4 x 10^4 x 10^4 grid, 10^12 batches of one design, a frequency response at 10^8
frequencies and a sensor latency of 10^9 ticks are each refused before any work, in one line
with the estimate, instead of dying with a MemoryError traceback; the sensor's delay line
grows with the ticks run, not with its latency (engine/memory.py,
engine/analysis/study_size.py).
"""
from __future__ import annotations

import os
import resource
import subprocess
import sys

import pytest
import yaml

from conftest import ROOT

#: Every test here runs the command line in subprocesses (seconds each).
pytestmark = pytest.mark.slow

LIMIT = 2 << 30


def _limited(*argv: str, cwd, code: str = "") -> subprocess.CompletedProcess:
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))

    cmd = [sys.executable, "-c", code] if code else [sys.executable, "-m", "flexure_sim.cli"]
    return subprocess.run([*cmd, *argv], cwd=cwd, preexec_fn=limit, capture_output=True,
                          text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"})


def _one_line(p: subprocess.CompletedProcess, prog: str) -> str:
    assert "Traceback" not in p.stderr and "MemoryError" not in p.stderr, p.stderr
    (line,) = p.stderr.strip().splitlines()
    assert line.startswith(f"{prog}: error: ")
    return line


NORMAL = {"normal": {"std": 5.0e-6}}
STUDIES = {
    "monte_carlo": ({"samples": 10**15, "seed": 1, "outputs": ["gain", "drive_force"],
                     "parameters": [{"name": "h", "path": "stiffness_models.notch.h", **NORMAL}]},
                    "samples: 1000000000000000 designs: their results would need ~"),
    "range": ({"outputs": ["gain"], "parameters": [
        {"name": "h", "path": "stiffness_models.notch.h",
         "range": {"start": 2.0e-4, "stop": 3.0e-4, "num": 10**9}}]},
        "parameters: a grid of 1000000000 designs: their results would need ~"),
    "grid": ({"outputs": ["gain"], "parameters": [
        {"name": n, "path": p, "range": {"start": a, "stop": b, "num": 10**4}}
        for n, p, a, b in (("h", "stiffness_models.notch.h", 2.0e-4, 3.0e-4),
                           ("D", "stiffness_models.notch.D", 2.9e-3, 3.1e-3),
                           ("m", "bodies.body4.mass", 0.01, 0.02))]},
        "parameters: a grid of 10000 x 10000 x 10000 = 1000000000000 designs: their results"),
    "batches": ({"samples": 10**12, "seed": 1, "batch_size": 1, "outputs": ["gain"],
                 "parameters": [{"name": "h", "path": "stiffness_models.notch.h", **NORMAL}]},
                "and 1000000000000 batches); make the study smaller or split it"),
}


@pytest.mark.parametrize("case", sorted(STUDIES))
def test_a_study_too_large_to_hold_is_refused_at_load_with_the_estimate(tmp_path, case):
    doc, expected = STUDIES[case]
    study = tmp_path / "big.yaml"
    study.write_text(yaml.safe_dump({"mechanism": "microstage", **doc}))
    p = _limited("sweep", str(study), "-o", str(tmp_path / "big.parquet"), cwd=tmp_path)
    assert p.returncode == 1
    line = _one_line(p, "flexure-sim sweep")
    assert expected in line and "this process can use" in line, line
    assert list(tmp_path.iterdir()) == [study]  # nothing written, no parts to resume


def test_a_frequency_response_too_large_to_hold_is_refused_with_the_estimate(tmp_path):
    p = _limited("frf", "microstage", "--points", "1e8", "-o", str(tmp_path / "frf"),
                 cwd=tmp_path)
    assert p.returncode == 2
    line = _one_line(p, "flexure-sim frf")
    assert "100000000 frequencies of 1 output(s)" in line and "would need ~" in line, line
    assert not (tmp_path / "frf").exists()


def test_a_sensor_latency_too_long_to_hold_is_refused_naming_the_key(tmp_path):
    doc = yaml.safe_load((ROOT / "config" / "microstage.yaml").read_text())
    doc["sensor"] = {"latency": 10**9}
    path = tmp_path / "late.yaml"
    path.write_text(yaml.safe_dump(doc))
    p = _limited("simulate", str(path), "--static", cwd=tmp_path)
    assert p.returncode == 2
    line = _one_line(p, "flexure-sim")
    assert "sensor.latency: 1000000000 ticks" in line and "at most 1000000 ticks" in line, line


def test_the_sensors_delay_line_grows_with_the_ticks_run_not_with_its_latency(tmp_path):
    """A latency of 10^9 ticks (past the loader's limit, built directly): 1000 ticks run."""
    code = (
        "from flexure_sim.engine.actuators.sensor import Sensor, SensorSpec\n"
        "s = Sensor(SensorSpec(latency=10**9), 1e-3)\n"
        "out = [s.sample(float(k)) for k in range(1000)]\n"
        "assert out == [0.0] * 1000, out[:5]\n"  # before tick L: the first reading
        "s = Sensor(SensorSpec(latency=3), 1e-3)\n"
        "assert [s.sample(float(k)) for k in range(6)] == [0.0, 0.0, 0.0, 0.0, 1.0, 2.0]\n"
        "print('ok')\n")
    p = _limited(cwd=tmp_path, code=code)
    assert p.returncode == 0 and p.stdout == "ok\n", p.stderr
