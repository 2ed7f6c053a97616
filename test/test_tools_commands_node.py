"""
What the tools show of drive commands the node clamped, rejected or could not read.

A tip-tilt stage_node subprocess (lockstep, three drives p1-p3, stroke 0-15 um each) records
while a real rclpy peer sends, one tick apart: p3 1.0 m and -1.0 m (both far outside the
stroke: clamped to 15 um and 0), p1 NaN (rejected), p2 two bytes that are no Float64
(malformed, recorded on ``/drive/p2/displacement/rejected``) and p1 2 um (applied). Expected
counts are those of what the test sent. Then ``flexure-sim analyse`` must report them (text
and JSON), ``plot`` must draw p3's command within its stroke and mark the commands beyond
it, and every recorded diagnostics window must give the intake cost per command in
microseconds.
"""
from __future__ import annotations

import json
import math
import signal

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64

from flexure_sim import cli

from node_harness import NodeProcess, Peer, diagnostics_values, next_domain_id

DRIVES = ("p1", "p2", "p3")
INPUTS = [f"/drive/{d}/input" for d in DRIVES]
STROKE_UM = 15.0  # config/tiptilt_stage.yaml: every stack 0-15 um
GARBAGE = bytes.fromhex("0001")
#: (drive, command) in the order sent, one tick apart.
SENT = (("p3", 1.0), ("p1", math.nan), ("p2", GARBAGE), ("p1", 2e-6), ("p3", -1.0))
EXPECTED = {
    "p1": {"received": 2, "accepted": 1, "clamped": 0, "rejected": 1, "malformed": 0,
           "lost": 0},
    "p2": {"received": 1, "accepted": 0, "clamped": 0, "rejected": 1, "malformed": 1,
           "lost": 0},
    "p3": {"received": 2, "accepted": 2, "clamped": 2, "rejected": 0, "malformed": 0,
           "lost": 0},
}


def _counts_reached(peer: Peer) -> bool:
    last = peer.last("/diagnostics")
    if last is None:
        return False
    d = diagnostics_values(last)
    return all(d.get(f"commands_{name}_received") == str(c["received"])
               for name, c in EXPECTED.items())


@pytest.fixture(scope="module")
def clamped_run(tmp_path_factory):
    """Return the recording of the tip-tilt node given the commands of `SENT`."""
    work = tmp_path_factory.mktemp("tiptilt_commands")
    domain = next_domain_id()
    peer = Peer(domain)
    node = NodeProcess(work / "node", domain, {
        "mechanism": "tiptilt_stage", "time_mode": "lockstep", "sim_step": 1e-4,
        "publish_rate": 20.0, "record": True, "record_path": "tt.mcap"})
    peer.watch = node
    try:
        peer.subscribe("/diagnostics", DiagnosticArray)
        commands = peer.connect_drives(DRIVES, INPUTS)
        for _ in range(2):
            peer.tick(INPUTS)
        for drive, value in SENT:
            msg = value if isinstance(value, bytes) else Float64(data=value)
            peer.publish_acked(commands[drive], msg)  # in the reader before the next step
            for _ in range(2):
                peer.tick(INPUTS)
        for _ in range(40):  # until a diagnostics window has closed over every command
            if _counts_reached(peer):
                break
            peer.tick(INPUTS)
        peer.tick(INPUTS)
        peer.tick(INPUTS)
    finally:
        code = node.stop(signal.SIGINT)
        peer.close()
    assert code == 0, node.stderr
    assert "clamped" in node.stderr  # the node warned
    return node.cwd / "tt.mcap"


def _cli(capsys, *args) -> tuple[int, str, str]:
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
def test_analyse_reports_the_nodes_command_counts_per_drive(clamped_run, capsys):
    code, out, err = _cli(capsys, "analyse", clamped_run, "--json", "--no-static")
    assert code == 0, err
    counts = json.loads(out)["commands"]
    for name, expected in EXPECTED.items():
        got = counts["drives"][name]
        assert {k: got[k] for k in expected} == expected, name
    assert counts["rejected_messages"] == {"/drive/p2/displacement/rejected": 1}
    code, out, err = _cli(capsys, "analyse", clamped_run, "--no-static")
    assert code == 0, err
    lines = [ln for ln in out.splitlines() if ln.startswith("commands")]
    assert len(lines) == 1, out
    line = lines[0]
    assert "drive p1: 2 received, 1 accepted, 0 clamped, 1 rejected, 0 malformed" in line
    assert "drive p2: 1 received, 0 accepted, 0 clamped, 1 rejected, 1 malformed" in line
    assert "drive p3: 2 received, 2 accepted, 2 clamped, 0 rejected, 0 malformed" in line
    assert line.endswith("1 message(s) on the rejected channels")


@pytest.mark.slow
def test_plot_draws_a_clamped_command_within_the_stroke_and_marks_it(clamped_run, tmp_path):
    from flexure_sim.tools.run.plot import plot_run
    from flexure_sim.tools.run.runlog import load_run

    figures: dict = {}
    plot_run(load_run(clamped_run), tmp_path, figures=figures)
    try:
        axes = figures["drives_outputs"].axes
        p3 = axes[DRIVES.index("p3")]
        lines = {ln.get_label(): ln for ln in p3.get_lines()}
        command = lines["drive p3: command"]
        assert max(command.get_ydata()) == pytest.approx(STROKE_UM, rel=1e-12)
        assert min(command.get_ydata()) == pytest.approx(0.0, abs=1e-12)
        marks = [ln for label, ln in lines.items() if "beyond the stroke" in label]
        assert len(marks) == 1
        assert marks[0].get_label() == "drive p3: 2 commands beyond the stroke, clamped"
        assert sorted(marks[0].get_ydata()) == pytest.approx([0.0, STROKE_UM], abs=1e-9)
        low, high = p3.get_ylim()
        assert -0.2 * STROKE_UM < low and high < 1.2 * STROKE_UM
        # p1's NaN was dropped from its command line; p1 stayed within its stroke: no marks.
        p1 = {ln.get_label() for ln in axes[0].get_lines()}
        assert not any("beyond the stroke" in label for label in p1)
    finally:
        import matplotlib.pyplot as plt
        for fig in figures.values():
            plt.close(fig)


@pytest.mark.slow
def test_every_diagnostics_window_gives_the_intake_cost_per_command_in_microseconds(
        clamped_run):
    from rosbags.highlevel import AnyReader

    windows = []
    with AnyReader([clamped_run]) as reader:
        conns = [c for c in reader.connections if c.topic == "/diagnostics"]
        for c, _, raw in reader.messages(connections=conns):
            values = {kv.key: kv.value for kv in reader.deserialize(raw, c.msgtype)
                      .status[0].values}
            windows.append(values)
    taken_before = 0
    seen = 0
    for values in windows:
        taken = sum(int(values[f"commands_{d}_received"]) for d in DRIVES)
        mean_us = float(values["command_time_mean_us"])
        if taken > taken_before:
            seen += 1
            # Taking, decoding, checking and recording a command costs between a tenth of a
            # microsecond and a second on any machine: a value in seconds would be < 1e-1.
            assert 0.1 < mean_us < 1e6, (values["sim_time"], mean_us)
        else:
            assert mean_us == 0.0, values["sim_time"]
        taken_before = taken
    assert seen >= 2


@pytest.mark.slow
def test_one_drive_a_clamped_command_in_the_plot_and_the_counts_in_analyse(tmp_path, capsys):
    """The microstage (one drive, stroke from its file): 1 m sent, 2 um sent."""
    from flexure_sim.engine.mechanism.loader import load_mechanism
    from flexure_sim.tools.run.plot import plot_run
    from flexure_sim.tools.run.runlog import load_run

    stroke_um = load_mechanism("microstage").drives[0].stroke[1] * 1e6
    domain = next_domain_id()
    peer = Peer(domain)
    node = NodeProcess(tmp_path / "node", domain, {
        "time_mode": "lockstep", "publish_rate": 200.0, "record": True,
        "record_path": "ms.mcap"})
    peer.watch = node
    inputs = ["/drive/input"]
    try:
        peer.subscribe("/clock", Clock)
        peer.subscribe("/diagnostics", DiagnosticArray)
        peer.subscribe(inputs[0], Float64)
        drive = peer.publisher("/drive/displacement", Float64)
        peer.wait_for_publishers(inputs)
        peer.wait_for_subscribers(drive)
        for value in (1.0, 2e-6):
            peer.publish_acked(drive, Float64(data=value))
            for _ in range(5):
                peer.tick(inputs)
        for _ in range(100):  # until a diagnostics window has closed over both commands
            last = peer.last("/diagnostics")
            if last is not None and diagnostics_values(last).get("commands_received") == "2":
                break
            peer.tick(inputs)
    finally:
        code = node.stop(signal.SIGINT)
        peer.close()
    assert code == 0, node.stderr
    path = node.cwd / "ms.mcap"
    code, out, err = _cli(capsys, "analyse", path, "--no-static")
    assert code == 0, err
    assert ("commands (node's counters at the end of the run): 2 received, 2 accepted, "
            "1 clamped, 0 rejected, 0 malformed") in out
    assert out.rstrip().endswith("0 message(s) on the rejected channels")
    figures: dict = {}
    plot_run(load_run(path), tmp_path / "plots", figures=figures)
    try:
        ax = figures["input_output"].axes[0]
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        assert max(lines["drive command"].get_ydata()) == pytest.approx(stroke_um, rel=1e-12)
        mark = lines["1 command beyond the stroke, clamped"]
        assert list(mark.get_ydata()) == pytest.approx([stroke_um], rel=1e-12)
        assert ax.get_ylim()[1] < 1.2 * stroke_um
    finally:
        import matplotlib.pyplot as plt
        for fig in figures.values():
            plt.close(fig)
