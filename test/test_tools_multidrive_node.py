"""
The tools on a run of the XY stage recorded through the real stage_node (issue 13, item 4).

A stage_node subprocess (lockstep, ``mechanism:=xy_stage``) records while a real rclpy peer
steps drive x, then drive y, tick by tick (as test_node_multidrive.py does). Acceptance:
``flexure-sim analyse`` of that recording reports the gain matrix that ``flexure-sim simulate
xy_stage --static --json`` computes by an independent static solve, to 1e-4 of its largest
entry. Then ``plot``, ``export`` and ``info`` of the same file show every drive and output.
"""
from __future__ import annotations

import csv
import json
import signal
import subprocess

import numpy as np
import pytest
from std_msgs.msg import Float64

from flexure_sim.tools.run.plot import figure_title

from node_harness import NodeProcess, Peer, next_domain_id

DRIVES = ("x", "y")
OUTPUTS = ("x", "y", "theta")
#: Step size: the static gain is the gain at rest; a step's gain is the secant over the step,
#: which for the platform's rotation differs from it by 2e-3 of the largest gain per um of
#: step (test_tools_multidrive.py): 10 nm keeps that below 2e-5.
U = 1e-8
RATE = 200.0
TICKS = 20        # per level: 100 ms, a hundred actuator time constants
INPUTS = [f"/drive/{d}/input" for d in DRIVES]


@pytest.fixture(scope="module")
def xy_run(tmp_path_factory):
    """Return the recording of the XY stage: x steps by U, then y (each held TICKS ticks)."""
    work = tmp_path_factory.mktemp("xy_node")
    domain = next_domain_id()
    peer = Peer(domain)
    node = NodeProcess(work / "node", domain, {
        "mechanism": "xy_stage", "time_mode": "lockstep", "sim_step": 1e-4,
        "publish_rate": RATE, "record": True, "record_path": "xy.mcap"})
    peer.watch = node
    try:
        commands = peer.connect_drives(DRIVES, INPUTS)
        for _ in range(TICKS):
            peer.tick(INPUTS)
        for k, drive in enumerate(DRIVES):
            commands[drive].publish(Float64(data=U))
            # The command is taken at the next tick whose step sees it: tick until it shows.
            for _ in range(50):
                peer.tick(INPUTS)
                if peer.last(INPUTS[k]).data > 0.0:
                    break
            for _ in range(TICKS - 1):
                peer.tick(INPUTS)
    finally:
        code = node.stop(signal.SIGINT)
        peer.close()
    assert code == 0, node.stderr
    return node.cwd / "xy.mcap"


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["flexure-sim", *args], capture_output=True, text=True, timeout=300)


def test_analyse_of_the_nodes_xy_recording_gives_simulate_statics_gain_matrix(xy_run):
    static = _cli("simulate", "xy_stage", "--static", "--json")
    assert static.returncode == 0, static.stderr
    expected = json.loads(static.stdout)["gain_matrix"]
    out = _cli("analyse", str(xy_run), "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    gm = result["gain_matrix"]
    assert gm["drives"] == expected["drives"] == list(DRIVES)
    assert gm["outputs"] == expected["outputs"] == list(OUTPUTS)
    measured, reference = np.array(gm["matrix"], dtype=float), np.array(expected["matrix"])
    scale = np.max(np.abs(reference))
    np.testing.assert_allclose(measured, reference, rtol=0, atol=1e-4 * scale)
    # One clean, settled step per drive, each seen by every output.
    assert [s["drive"] for s in result["steps"]] == list(DRIVES)
    assert all(s["clean"] and s["input_settled"] for s in result["steps"])
    assert [p["steps"] for p in result["pairs"]] == [1] * 6
    units = {(p["drive"], p["output"]): p["unit"] for p in result["pairs"]}
    assert units[("x", "x")] == "m/m" and units[("y", "theta")] == "rad/m"
    # The direct pairs settle within the dwell (the lag and the hinge modes, not the tick).
    direct = [p for p in result["pairs"] if p["drive"] == p["output"]]
    assert all(0.0 < p["settling_time"] < TICKS / RATE for p in direct)
    text = _cli("analyse", str(xy_run))
    assert text.returncode == 0, text.stderr
    assert "gain matrix" in text.stdout and "theta [rad]" in text.stdout


def test_plot_info_export_of_the_nodes_xy_recording(xy_run, tmp_path):
    out = _cli("plot", str(xy_run), "-o", str(tmp_path / "plots"))
    assert out.returncode == 0, out.stderr
    assert figure_title(tmp_path / "plots" / "drives_outputs.png") == "Drives and outputs"
    info = _cli("info", str(xy_run), "--json")
    assert info.returncode == 0, info.stderr
    s = json.loads(info.stdout)
    assert [d["name"] for d in s["drives"]] == list(DRIVES)
    assert [o["name"] for o in s["outputs"]] == list(OUTPUTS)
    text = _cli("info", str(xy_run)).stdout
    assert "Drives:" in text and "/drive/y/input" in text and "Outputs:" in text
    out = _cli("export", str(xy_run), "--csv", str(tmp_path / "csv"), "--signals")
    assert out.returncode == 0, out.stderr
    with (tmp_path / "csv" / "signals.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == [
        "time", "drive/x/displacement", "drive/x/input", "drive/x/force",
        "drive/y/displacement", "drive/y/input", "drive/y/force",
        "output/x/displacement", "output/y/displacement", "output/theta/displacement"]
    assert float(rows[-1]["drive/y/input"]) == pytest.approx(U, rel=1e-9)
