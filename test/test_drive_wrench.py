"""
The full wrench at a held drive tip (issue 30 item 4): force x, y and moment, not only the axis.

Expected values come from the hinges alone: the driven body is held by its drive and by the
hinges on it, so at rest (statics, or after the lag has settled) the drive's wrench is minus the
sum of the wrenches those hinges exert on it, moved to the body's origin with the lever arm of
each hinge frame -- a balance of the reported hinge wrenches (``Assembly`` frame b figures), not
the constraint forces the drive wrench is computed from.
"""
import json
import math
import subprocess
import sys

import numpy as np
import pytest
import yaml

from conftest import ROOT
from flexure_sim.engine.mechanism.loader import mechanism_from_dict
from flexure_sim.engine.solver.simulation import Simulation
from test_statics import DRIVEN_PLATFORM


def _moved_to_origin(wrench_b, at, angle=0.0) -> np.ndarray:
    """
    Return a wrench (moment, fx, fy) given in a frame at ``at`` turned by ``angle`` (body frame).

    As (moment about the body's origin, fx, fy along the body's axes): f = R(angle) f_b,
    moment = m_b + at x f.
    """
    m, fx_b, fy_b = wrench_b
    c, s = math.cos(angle), math.sin(angle)
    fx, fy = c * fx_b - s * fy_b, s * fx_b + c * fy_b
    return np.array([m + at[0] * fy - at[1] * fx, fx, fy])


def _cli(*args) -> dict:
    p = subprocess.run([sys.executable, "-m", "flexure_sim.cli", "simulate", *args, "--json"],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def _stage_hinge_a_frame_b():
    """Frame b of the stage's hinge a (on body6, the driven body), from the mechanism file."""
    doc = yaml.safe_load((ROOT / "config" / "microstage.yaml").read_text())
    hinge = next(h for h in doc["hinges"] if h["name"] == "a")
    assert hinge["b"]["body"] == "body6"
    at = hinge["b"]["at"]
    return at[:2], (at[2] if len(at) > 2 else 0.0)


@pytest.mark.parametrize("mode", [["--static"], ["--duration", "0.05"]])
def test_the_stage_reports_its_drive_wrench_in_full(mode):
    """
    ``simulate microstage --json``: the drive's wrench balances hinge a's on body6.

    Statically, and 50 ms after the step (the 1 ms lag has settled to e^-50: no inertia left);
    the axis component is the drive force, and the shear and moment are not zero.
    """
    out = _cli("microstage", "--drive", "step:1.35e-6", *mode)
    at, angle = _stage_hinge_a_frame_b()
    hinge = _moved_to_origin(out["hinges"]["a"]["wrench_on_b"], at, angle)
    w = out["drives"]["drive"]["wrench"]
    assert w["frame"] == "body6"
    got = np.array([w["moment"], w["force_x"], w["force_y"]])
    np.testing.assert_allclose(got, -hinge, rtol=1e-9, atol=1e-12 * abs(got[1]))
    assert w["force_x"] == pytest.approx(out["drive_force"], rel=1e-12)
    assert abs(w["force_y"]) > 1e-3 and abs(w["moment"]) > 1e-6


def test_a_rotated_driven_body_reports_its_wrench_in_its_own_frame():
    """
    The driven platform at 0.3 rad: the wrench is turned into its frame, moment about its origin.

    The platform is held by one hinge (frame b where it was, at -0.3 rad in the turned body), so
    the drive's wrench is minus that hinge's, moved to the origin; the drive force is the
    wrench's component along the drive axis (x of the root frame, at -0.3 rad in the body's
    frame).
    """
    doc = json.loads(json.dumps(DRIVEN_PLATFORM))
    doc["bodies"][1]["pose"] = [0.01, 0.0, 0.3]
    at = (-0.005 * math.cos(0.3), 0.005 * math.sin(0.3))      # R(-0.3) (-0.005, 0)
    doc["hinges"][0]["b"]["at"] = [at[0], at[1], -0.3]
    snap = Simulation(mechanism_from_dict(doc)).static(1e-6).snapshot
    hinge = _moved_to_origin(snap.wrenches[0], at, -0.3)
    np.testing.assert_allclose(snap.drive_wrenches[0], -hinge, rtol=1e-9,
                               atol=1e-12 * np.abs(hinge).max())
    _, fx, fy = snap.drive_wrenches[0]
    along_axis = math.cos(0.3) * fx - math.sin(0.3) * fy   # root x in the body's frame
    assert along_axis == pytest.approx(snap.drive_forces[0], rel=1e-12)
    assert abs(fy) > 1e-3 * abs(fx)
