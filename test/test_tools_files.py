"""
flexure-sim info / analyse / plot / export on recordings written without DDS (tools_fixtures).

Also on bad files: truncated at several offsets, flipped bytes, empty, not MCAP, MCAP of another
profile, rosbag2 files of other topics. Bad files give a message naming the file and the problem,
exit code 1 (2 for bad usage), and never a traceback.
"""
from __future__ import annotations

import csv
import json
import subprocess
import sys
import types
from pathlib import Path

import pytest
from mcap.records import Chunk, Message
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk
from mcap.writer import Writer
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64, String

from flexure_sim import cli
from flexure_sim.recording import McapRecorder, read_log
from flexure_sim.tools.run.export import csv_name
from flexure_sim.tools.run.plot import figure_title
from flexure_sim.tools.run.runlog import RunError, find_namespace

from tools_fixtures import DEMO_LEVELS, live_gains, record_long_run, record_stage_run
from reference_figures import JOINT_A_COMPRESSION, STAGE_GAIN, STAGE_INPUT

ROOT = Path(__file__).resolve().parent.parent


def flexure_sim(capsys, *args: str) -> tuple[int, str, str]:
    """Run ``flexure-sim ARGS`` in-process; (exit code, stdout, stderr)."""
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def stage(tmp_path_factory):
    """Return a demo-profile run of the stage, in several chunks, and what the 'live' run saw."""
    path = tmp_path_factory.mktemp("stage") / "stage.mcap"
    live = record_stage_run(path, chunk_size=32 * 1024)
    return path, live


@pytest.fixture(scope="module")
def stage_nocmd(tmp_path_factory):
    path = tmp_path_factory.mktemp("nocmd") / "nocmd.mcap"
    return path, record_stage_run(path, record_command=False, metadata=False)


@pytest.fixture(scope="module")
def fourbar(tmp_path_factory):
    path = tmp_path_factory.mktemp("fourbar") / "fourbar.mcap"
    record_stage_run(path, mechanism="fourbar_mixed", levels=(), rest=0.05)
    return path


# ------------------------------------------------------------------------------ info
def test_info_shows_topics_counts_duration_mechanism_and_parameters(capsys, stage):
    path, _ = stage
    code, out, err = flexure_sim(capsys, "info", path)
    assert code == 0, err
    assert "/output/displacement" in out and "std_msgs/msg/Float64" in out
    assert "/hinges/a/wrench" in out and "geometry_msgs/msg/WrenchStamped" in out
    assert "Duration:     0.109000 s" in out
    assert "Mechanism:    microstage" in out
    for param in (
        "publish_rate  1000.0 Hz",
        "sim_step      0.0001 s",
        "stroke_max    2e-06 m",
        "time_mode     fast",
    ):
        assert param in out
    code, out, _ = flexure_sim(capsys, "info", path, "--json")
    info = json.loads(out)
    counts = {t["name"]: t["count"] for t in info["topics"]}
    assert counts["/output/displacement"] == 110 and counts["/drive/displacement"] == len(
        DEMO_LEVELS
    )
    assert info["mechanism"]["name"] == "microstage" and info["parameters"]["sim_step"] == "0.0001"
    assert info["duration"] == pytest.approx(0.109)
    assert info["message_count"] == sum(counts.values())


def test_info_of_a_file_without_flexure_sim_metadata_says_so(capsys, stage_nocmd):
    code, out, _ = flexure_sim(capsys, "info", stage_nocmd[0])
    assert code == 0 and "not recorded" in out


# ------------------------------------------------------------------------------ analyse
def test_analyse_gives_the_live_gains_and_the_engines_static_gain(capsys, stage):
    path, live = stage
    code, out, err = flexure_sim(capsys, "analyse", path, "--json")
    assert code == 0, err
    steps = json.loads(out)
    assert [s["input"] for s in steps] == list(DEMO_LEVELS)
    for s, g in zip(steps, live_gains(live)):
        for key in (
            "input",
            "gain",
            "settling_time",
            "overshoot",
            "joint_a_compression",
            "peak_drive_force",
        ):
            assert key in s
        assert s["settled"]
        assert s["gain"] == pytest.approx(g, rel=1e-12)
        assert s["gain"] == pytest.approx(s["static_gain"], rel=1e-6)
        assert s["gain"] == pytest.approx(STAGE_GAIN, rel=1e-4)
        assert 1e-3 < s["settling_time"] < 5e-3 and 0 <= s["overshoot"] < 0.01
        assert set(s["peak_wrench"]) == set("abcdefg")
    # Joint-a compression and drive force at 2 um: the engine's statics, scaled (linear stage).
    assert steps[3]["joint_a_compression"] == pytest.approx(
        2e-6 / STAGE_INPUT * JOINT_A_COMPRESSION, rel=2e-3)
    assert steps[3]["peak_drive_force"] >= steps[3]["drive_force"] > 0
    code, out, _ = flexure_sim(capsys, "analyse", path)
    assert code == 0
    assert f"{STAGE_GAIN:.3f}" in out and "joint-a compr. [nm]" in out and "peak hinge load" in out


def test_analyse_finds_the_steps_in_the_drive_input_when_the_command_was_not_recorded(
    capsys, stage, stage_nocmd
):
    code, out, err = flexure_sim(capsys, "analyse", stage_nocmd[0], "--json")
    assert code == 0
    assert "steps found in /drive/input" in err
    assert "no static comparison" in err  # no metadata: the mechanism is unknown
    steps = json.loads(out)
    assert len(steps) == len(DEMO_LEVELS)
    for s, g in zip(steps, live_gains(stage_nocmd[1])):
        assert s["gain"] == pytest.approx(g, rel=1e-12)
        assert s["static_gain"] is None


def test_plot_without_the_mechanism_draws_the_recorded_compression(capsys, stage_nocmd, tmp_path):
    code, out, err = flexure_sim(capsys, "plot", stage_nocmd[0], "-o", tmp_path)
    assert code == 0, err
    assert figure_title(tmp_path / "joint_a.png") == "Joint a compression"
    assert figure_title(tmp_path / "input_output.png") == "Input and output displacement"


def test_a_bag_recorded_on_the_wall_clock_is_analysed_in_simulation_time_from_clock(
    capsys, stage, tmp_path
):
    """
    ``ros2 bag record`` (no --use-sim-time) of a fast-mode run.

    Log times are reception times on the wall clock; /clock gives the simulation time back.
    """
    path = tmp_path / "wall.mcap"
    record_stage_run(path, wall_clock=(1_763_000_000_000_000_000, 0.2))
    code, out, err = flexure_sim(capsys, "analyse", path, "--json")
    assert code == 0, err
    assert "simulation time is taken from the recorded /clock" in err
    wall = json.loads(out)
    _, out, _ = flexure_sim(capsys, "analyse", stage[0], "--json")
    for w, s in zip(wall, json.loads(out)):
        assert w["t"] == pytest.approx(s["t"], abs=1e-12)
        assert w["gain"] == pytest.approx(s["gain"], rel=1e-12)
        assert w["settling_time"] == pytest.approx(s["settling_time"], rel=1e-9)


def test_analyse_of_a_namespaced_stage(capsys, tmp_path):
    path = tmp_path / "ns.mcap"
    live = record_stage_run(path, levels=(1.35e-6,), namespace="/left", clock=False)
    code, out, err = flexure_sim(capsys, "analyse", path, "--json")
    assert code == 0, err
    assert json.loads(out)[0]["gain"] == pytest.approx(live_gains(live)[0], rel=1e-12)
    code, _, err = flexure_sim(capsys, "analyse", path, "--namespace", "/right")
    assert code == 2 and "no stage topics under namespace '/right'" in err


def test_two_stages_in_one_file_need_a_namespace():
    log = types.SimpleNamespace(
        path=Path("two.mcap"), topics={"/a/output/displacement": 0, "/b/output/displacement": 0}
    )
    with pytest.raises(RunError, match="choose one with --namespace"):
        find_namespace(log)
    assert find_namespace(log, "b") == "/b"


def test_analyse_refuses_a_run_without_a_drive_and_plot_still_draws_it(capsys, fourbar, tmp_path):
    code, _, err = flexure_sim(capsys, "analyse", fourbar)
    assert code == 1 and "/output/displacement" in err and "fourbar_mixed" in err
    code, out, err = flexure_sim(capsys, "plot", fourbar, "-o", tmp_path / "p")
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / "p").iterdir()) == [
        "body_poses.png",
        "hinge_wrenches.png",
    ]


def test_bad_usage_exits_2(capsys, stage, tmp_path):
    assert flexure_sim(capsys, "analyse", stage[0], "--band", "2")[0] == 2
    code, _, err = flexure_sim(capsys, "analyse", tmp_path / "missing.mcap")
    assert code == 2 and "no such file" in err
    code, _, err = flexure_sim(capsys, "info", tmp_path)
    assert code == 2 and "is a directory" in err
    code, _, err = flexure_sim(
        capsys, "export", stage[0], "--csv", tmp_path / "c", "--topics", "/nope"
    )
    assert code == 2 and "/nope" in err


# ------------------------------------------------------------------------------ plot, export
def test_plot_writes_the_figures_with_their_titles(capsys, stage, tmp_path):
    code, out, err = flexure_sim(capsys, "plot", stage[0], "-o", tmp_path / "plots")
    assert code == 0, err
    expected = {
        "input_output.png": "Input and output displacement",
        "joint_a.png": "Joint a displacement on body2 and body6",
        "hinge_wrenches.png": "Hinge wrenches",
        "drive_force.png": "Drive force",
    }
    for name, title in expected.items():
        png = tmp_path / "plots" / name
        assert png.stat().st_size > 10_000
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert figure_title(png) == title
        assert name in out


def test_joint_frame_displacements_differ_by_the_recorded_compression(stage):
    from flexure_sim.tools.run.runlog import load_run

    run = load_run(stage[0])
    t, da, db, body_a, body_b = run.hinge_frame_displacements("a")
    assert (body_a, body_b) == ("body2", "body6")
    comp = run.scalar("hinges/a/compression")
    assert list(t) == list(comp.t)
    assert (db[:, 0] - da[:, 0]) == pytest.approx(comp.values, abs=1e-15)
    # body6 is driven along x: its frame moves with the drive input.
    assert db[:, 0] == pytest.approx(run.scalar("drive/input").values, abs=1e-15)


def test_export_writes_one_csv_per_topic_with_a_row_per_message(capsys, stage, tmp_path):
    path, _ = stage
    code, out, err = flexure_sim(capsys, "export", path, "--csv", tmp_path / "csv")
    assert code == 0, err
    log = read_log(path)
    files = sorted(p.name for p in (tmp_path / "csv").iterdir())
    assert files == sorted(csv_name(t) for t in log.topics)
    for topic, info in log.topics.items():
        with open(tmp_path / "csv" / csv_name(topic), newline="") as f:
            rows = list(csv.DictReader(f))
        assert len(rows) == info.message_count
        times = [round(float(r["time"]) * 1e9) for r in rows]
        assert times == [m.log_time_ns for m in log.messages_on(topic)]
    with open(tmp_path / "csv" / "hinges.a.wrench.csv", newline="") as f:
        reader = csv.DictReader(f)
        first = next(reader)
    assert reader.fieldnames[:4] == [
        "time",
        "header/stamp/sec",
        "header/stamp/nanosec",
        "header/frame_id",
    ]
    assert first["header/frame_id"] == "hinge_a"
    msg = log.messages_on("/hinges/a/wrench")[0].message
    assert float(first["wrench/force/x"]) == msg.wrench.force.x  # full precision
    with open(tmp_path / "csv" / "diagnostics.csv", newline="") as f:
        assert "status[0]/values/sim_time" in next(csv.reader(f))
    code, out, _ = flexure_sim(
        capsys, "export", path, "--csv", tmp_path / "one", "--topics", "/drive/force"
    )
    assert code == 0 and [p.name for p in (tmp_path / "one").iterdir()] == ["drive.force.csv"]


# ------------------------------------------------------------------------------ bad files
TOOLS = (("info",), ("analyse",), ("plot", "-o", "PLOTS"), ("export", "--csv", "CSV"))


def run_tool(capsys, tool: tuple, path: Path, tmp_path: Path, *extra: str) -> tuple[int, str, str]:
    args = [
        a.replace("PLOTS", str(tmp_path / "plots")).replace("CSV", str(tmp_path / "csv"))
        for a in tool
    ]
    return flexure_sim(capsys, args[0], path, *args[1:], *extra)


def assert_clean_failure(code: int, out: str, err: str, path: Path, *words: str) -> None:
    assert code == 1, (code, out, err)
    assert "Traceback" not in err and "Traceback" not in out
    assert err.startswith("flexure-sim ") and str(path) in err
    for w in words:
        assert w in err, err


@pytest.fixture(scope="module")
def chunk_offsets(stage):
    from flexure_sim.recording.scan import scan_file

    scan = scan_file(stage[0])
    assert len(scan.chunk_offsets) > 4
    return scan.chunk_offsets


@pytest.mark.parametrize("where", ["magic", "header", "chunk1", "mid", "summary", "last_byte"])
def test_a_truncated_file_is_refused_with_what_was_readable(
    capsys, stage, chunk_offsets, tmp_path, where
):
    src = stage[0]
    data = src.read_bytes()
    cut = {"magic": 5, "header": 30, "chunk1": chunk_offsets[1] + 100, "mid": len(data) // 2,
           "summary": len(data) - 300, "last_byte": len(data) - 1}[where]
    bad = tmp_path / f"cut_{where}.mcap"
    bad.write_bytes(data[:cut])
    for tool in TOOLS:
        code, out, err = run_tool(capsys, tool, bad, tmp_path)
        assert_clean_failure(code, out, err, bad, "readable")
    if where in ("chunk1", "mid", "summary"):
        _, _, err = run_tool(capsys, ("analyse",), bad, tmp_path)
        assert "--recover" in err


def test_recover_analyses_the_readable_part_of_a_truncated_file(
    capsys, stage, chunk_offsets, tmp_path
):
    data = stage[0].read_bytes()
    bad = tmp_path / "killed.mcap"
    bad.write_bytes(data[: int(len(data) * 0.7)])
    code, out, err = flexure_sim(capsys, "analyse", bad, "--recover", "--json")
    assert code == 0, err
    assert "incomplete file" in err and "recovered" in err and "Traceback" not in err
    part = json.loads(out)
    code, out, _ = flexure_sim(capsys, "analyse", stage[0], "--json")
    full = json.loads(out)
    assert 0 < len(part) <= len(full)
    for p, f in zip(part[:-1], full):  # every step but the last is complete in the prefix
        assert p["gain"] == f["gain"] and p["settling_time"] == f["settling_time"]
    for tool in (("info",), ("plot", "-o", "PLOTS"), ("export", "--csv", "CSV")):
        code, _, err = run_tool(capsys, tool, bad, tmp_path, "--recover")
        assert code == 0, err
    # Nothing readable at all: still a clean failure.
    empty_prefix = tmp_path / "head.mcap"
    empty_prefix.write_bytes(data[:chunk_offsets[0] + 50])
    code, out, err = flexure_sim(capsys, "analyse", empty_prefix, "--recover")
    assert_clean_failure(code, out, err, empty_prefix, "nothing readable")


def test_flipped_bytes_give_a_clear_error_or_a_correct_answer_never_a_traceback(
    capsys, stage, chunk_offsets, tmp_path
):
    data = stage[0].read_bytes()
    positions = sorted(
        set(range(8, len(data), len(data) // 23)) | {chunk_offsets[2] + 200, 12, len(data) - 20}
    )
    failures = 0
    for pos in positions:
        bad = tmp_path / "flipped.mcap"
        b = bytearray(data)
        b[pos] ^= 0xFF
        bad.write_bytes(bytes(b))
        code, out, err = flexure_sim(capsys, "analyse", bad, "--json")
        assert "Traceback" not in err and code in (0, 1), (pos, code, err)
        if code == 1:
            failures += 1
            assert str(bad) in err
        if pos == chunk_offsets[2] + 200:  # inside a chunk's messages: the CRC catches it
            assert code == 1 and "crc" in err.lower()
    assert failures >= len(positions) - 3  # only bytes that carry no checked content may pass


def test_an_empty_file_and_a_text_file_are_refused(capsys, tmp_path):
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    text = tmp_path / "notes.mcap"
    text.write_text("these are not the bytes you are looking for\n")
    for tool in TOOLS:
        assert_clean_failure(*run_tool(capsys, tool, empty, tmp_path), empty, "empty")
        assert_clean_failure(*run_tool(capsys, tool, text, tmp_path), text, "not an MCAP file")


def test_an_mcap_of_another_profile_is_refused(capsys, tmp_path):
    path = tmp_path / "json.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="test")
        sid = w.register_schema(name="Point", encoding="jsonschema", data=b'{"type": "object"}')
        cid = w.register_channel(
            topic="/output/displacement", message_encoding="json", schema_id=sid
        )
        for k in range(10):
            w.add_message(
                channel_id=cid, log_time=k * 1000, publish_time=k * 1000, data=b'{"x": 1}'
            )
        w.finish()
    for tool in TOOLS:
        assert_clean_failure(*run_tool(capsys, tool, path, tmp_path), path, "not a rosbag2 log")


def test_a_rosbag2_file_of_other_topics_is_summarised_but_not_analysed(capsys, tmp_path):
    path = tmp_path / "chatter.mcap"
    with McapRecorder(path) as rec:
        rec.add_topic("/chatter", "std_msgs/msg/String")
        rec.add_topic("/temperature", "std_msgs/msg/Float64")
        for k in range(5):
            rec.write("/chatter", serialize_message(String(data=f"hello {k}")), k * 1_000_000)
            rec.write("/temperature", serialize_message(Float64(data=20.0 + k)), k * 1_000_000)
    code, out, _ = flexure_sim(capsys, "info", path)
    assert code == 0 and "/chatter" in out and "not recorded" in out
    assert_clean_failure(
        *run_tool(capsys, ("analyse",), path, tmp_path), path, "/output/displacement", "/chatter"
    )
    assert_clean_failure(
        *run_tool(capsys, ("plot", "-o", "PLOTS"), path, tmp_path), path, "nothing to plot"
    )
    code, out, _ = run_tool(capsys, ("export", "--csv", "CSV"), path, tmp_path)
    assert code == 0
    assert (tmp_path / "csv" / "chatter.csv").read_text().splitlines()[1] == "0.000000000,hello 0"


def test_the_installed_command_prints_no_traceback_for_a_damaged_file(stage, tmp_path):
    bad = tmp_path / "cut.mcap"
    bad.write_bytes(stage[0].read_bytes()[:5000])
    for tool in (
        ["info"],
        ["analyse"],
        ["plot", "-o", str(tmp_path / "p")],
        ["export", "--csv", str(tmp_path / "c")],
    ):
        proc = subprocess.run(
            [sys.executable, "-m", "flexure_sim.cli", tool[0], str(bad), *tool[1:]],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=120,
        )
        assert proc.returncode == 1, proc.stderr
        assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1
        assert "truncated" in proc.stderr and "readable" in proc.stderr


# ------------------------------------------------------------------------------ undecodable
def test_a_message_that_does_not_decode_is_skipped_counted_and_kept(capsys, tmp_path):
    """
    A run whose command at 15 ms was recorded as the 2 bytes another node published.

    The tools skip it and say so, info counts it, the bytes stay in the file, --strict refuses.
    """
    path = tmp_path / "odd.mcap"
    record_stage_run(path, extra_commands=[(0.015, 1e-6)], chunk_size=32 * 1024)
    odd = tmp_path / "odd_bytes.mcap"
    log = read_log(path)
    with McapRecorder(odd, chunk_size=32 * 1024) as rec:
        for name, topic in log.topics.items():
            rec.add_topic(name, topic.type)
        rec.add_metadata("flexure_sim", log.metadata["flexure_sim"])
        for m in log.messages:
            data = m.data
            if m.topic == "/drive/displacement" and m.log_time_ns == 15_000_000:
                data = bytes.fromhex("0001")  # what a misbehaving node may publish
            rec.write(m.topic, data, m.log_time_ns)
    note = "1 undecodable message on /drive/displacement"
    code, out, err = flexure_sim(capsys, "analyse", odd, "--json")
    assert code == 0 and err.count(note) == 1, err
    # The steps are those of the demo levels alone (every 20 ms from 10 ms): the 1 um at
    # 15 ms is unknown to the analysis.
    assert [round(s["t"], 9) for s in json.loads(out)] == [
        round(0.01 + 0.02 * k, 9) for k in range(len(DEMO_LEVELS))]
    code, out, err = flexure_sim(capsys, "info", odd, "--json")
    assert code == 0 and json.loads(out)["undecodable"] == {"/drive/displacement": 1}, err
    code, out, err = flexure_sim(capsys, "info", odd, "--json", "--no-decode")
    assert code == 0 and json.loads(out)["undecodable"] is None, err
    code, out, err = flexure_sim(capsys, "export", odd, "--csv", tmp_path / "csv")
    assert code == 0 and note in err
    with open(tmp_path / "csv" / "drive.displacement.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == log.counts["/drive/displacement"] - 1
    raw = read_log(odd, decode=False).messages_on("/drive/displacement")
    assert bytes.fromhex("0001") in [m.data for m in raw]  # kept in the file
    for tool in TOOLS:
        code, out, err = run_tool(capsys, tool, odd, tmp_path, "--strict")
        assert_clean_failure(code, out, err, odd, "does not decode", "--strict")


# ------------------------------------------------------------------------------ damaged chunks
def flip_bit_in_chunk(data: bytes, chunk_offset: int, where: int = 500) -> bytes:
    """
    Return ``data`` with one bit flipped ``where`` bytes into the chunk record at ``chunk_offset``.

    The offset is past the record's header fields: inside its records.
    """
    b = bytearray(data)
    b[chunk_offset + where] ^= 0x04
    return bytes(b)


def independent_crc_check(path: Path) -> None:
    """Raise CRCValidationError if the mcap library's own reader finds a CRC mismatch."""
    with open(path, "rb") as f:
        for _ in StreamReader(f, validate_crcs=True).records:
            pass


def test_a_bit_flipped_inside_a_chunk_is_reported_by_every_tool(
    capsys, stage, chunk_offsets, tmp_path
):
    data = stage[0].read_bytes()
    bad = tmp_path / "flipped.mcap"
    bad.write_bytes(flip_bit_in_chunk(data, chunk_offsets[2]))
    with pytest.raises(CRCValidationError):
        independent_crc_check(bad)
    full = read_log(stage[0])
    for tool in TOOLS:
        code, out, err = run_tool(capsys, tool, bad, tmp_path)
        assert_clean_failure(code, out, err, bad, "chunk 3 ", "CRC mismatch", "readable",
                             "--recover")
    # --recover reads every other chunk, the ones after the damaged chunk included.
    code, out, err = flexure_sim(capsys, "info", bad, "--recover", "--json")
    assert code == 0, err
    info = json.loads(out)
    assert not info["complete"] and "chunk 3 " in info["note"] and "CRC mismatch" in info["note"]
    with open(stage[0], "rb") as f:
        chunks = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    lost = sum(1 for r in breakup_chunk(chunks[2]) if isinstance(r, Message))
    assert info["message_count"] == full.message_count - lost > 0
    intact = json.loads(flexure_sim(capsys, "info", stage[0], "--json")[1])
    assert info["end"] == pytest.approx(intact["end"])
    for tool in TOOLS[1:]:
        code, out, err = run_tool(capsys, tool, bad, tmp_path, "--recover")
        assert code == 0 and "chunk 3 " in err and "Traceback" not in err, (tool, err)
    code, out, _ = flexure_sim(capsys, "analyse", bad, "--recover", "--json")
    steps = {s["t"]: s for s in json.loads(out)}
    code, out, _ = flexure_sim(capsys, "analyse", stage[0], "--json")
    reference = {s["t"]: s for s in json.loads(out)}
    # Every step whose command was not in chunk 3 is found (the chunk's log-time span, from
    # the intact file), those after the damage with the gains of the intact file.
    lo, hi = chunks[2].message_start_time * 1e-9, chunks[2].message_end_time * 1e-9
    lost_steps = [t for t in sorted(reference) if lo <= t <= hi]
    assert sorted(steps) == [t for t in sorted(reference) if t not in lost_steps], (lo, hi)
    for t in (0.07, 0.09):
        assert steps[t]["gain"] == reference[t]["gain"] is not None


def test_a_chunk_whose_length_is_damaged_is_stepped_over_with_the_chunk_index(
        capsys, stage, chunk_offsets, tmp_path):
    """
    A flipped bit in a chunk record's length field breaks the framing.

    The next record cannot be found by reading on, but the summary's chunk index says where the
    next chunk starts, so --recover still reads every chunk after the damaged one.
    """
    data = bytearray(stage[0].read_bytes())
    data[chunk_offsets[2] + 1 + 2] ^= 0x10  # opcode, then the u64 length: +1 MiB
    bad = tmp_path / "length.mcap"
    bad.write_bytes(bytes(data))
    for tool in TOOLS:
        code, out, err = run_tool(capsys, tool, bad, tmp_path)
        assert_clean_failure(code, out, err, bad, "chunk 3 ", "does not parse", "--recover")
    code, out, err = flexure_sim(capsys, "analyse", bad, "--recover", "--json")
    assert code == 0 and f"reading resumed at byte {chunk_offsets[3]}" in err, err
    steps = {round(s["t"], 9): s["gain"] for s in json.loads(out)}
    code, out, _ = flexure_sim(capsys, "analyse", stage[0], "--json")
    reference = {round(s["t"], 9): s["gain"] for s in json.loads(out)}
    with open(stage[0], "rb") as f:
        chunks = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    lo, hi = chunks[2].message_start_time * 1e-9, chunks[2].message_end_time * 1e-9
    lost_steps = [t for t in sorted(reference) if lo <= t <= hi]  # commands in chunk 3
    assert sorted(steps) == [t for t in sorted(reference) if t not in lost_steps], (lo, hi)
    assert all(steps[t] == reference[t] for t in (0.07, 0.09))


# ------------------------------------------------------------------------------ other writers
@pytest.fixture(scope="module")
def rosbags_files(stage, tmp_path_factory):
    """
    Return the stage run converted by rosbags-convert.

    It is converted to a sqlite3 bag and back to MCAP, and directly to an MCAP bag with
    zstd-compressed chunks (both rosbag2 MCAP written by rosbags, with ``custom_data: null`` in
    their metadata).
    """
    root = tmp_path_factory.mktemp("rosbags")
    convert = [sys.executable, "-m", "rosbags.convert"]

    def run(*args: str) -> None:
        proc = subprocess.run([*convert, *args], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr

    run("--src", str(stage[0]), "--dst", str(root / "db3"), "--dst-storage", "sqlite3")
    run("--src", str(root / "db3"), "--dst", str(root / "back"), "--dst-storage", "mcap")
    run("--src", str(stage[0]), "--dst", str(root / "zstd"), "--dst-storage", "mcap",
        "--compress", "zstd", "--compress-mode", "storage")
    return {"via sqlite3": root / "back" / "back.mcap", "zstd": root / "zstd" / "zstd.mcap"}


@pytest.mark.parametrize("route", ["via sqlite3", "zstd"])
def test_every_tool_reads_a_rosbag2_mcap_written_by_rosbags(capsys, stage, rosbags_files, route,
                                                            tmp_path):
    path = rosbags_files[route]
    assert "custom_data: null" in read_log(path).metadata["rosbag2"]["serialized_metadata"]
    code, out, err = flexure_sim(capsys, "info", path, "--json")
    assert code == 0 and "Traceback" not in err, err
    info = json.loads(out)
    assert info["library"].startswith("rosbags") and info["complete"]
    original = read_log(stage[0])
    assert {t["name"]: t["count"] for t in info["topics"]} == original.counts
    assert info["dropped_messages"] is None and info["undecodable"] == {}
    assert info["unchecked_chunks"] == info["chunk_count"] == 1  # rosbags writes no CRCs
    code, out, err = flexure_sim(capsys, "info", path)
    assert code == 0 and "/output/displacement" in out, err
    assert "no CRC" in out
    code, out, err = flexure_sim(capsys, "analyse", path, "--json")
    assert code == 0, err
    code, ref, _ = flexure_sim(capsys, "analyse", stage[0], "--json")
    gains = [s["gain"] for s in json.loads(out)]
    assert gains == [s["gain"] for s in json.loads(ref)] and all(g is not None for g in gains)
    code, out, err = flexure_sim(capsys, "plot", path, "-o", tmp_path / "plots")
    assert code == 0 and (tmp_path / "plots" / "input_output.png").exists(), err
    code, out, err = flexure_sim(capsys, "export", path, "--csv", tmp_path / "csv")
    assert code == 0, err
    for topic, count in original.counts.items():
        with open(tmp_path / "csv" / csv_name(topic), newline="") as f:
            assert sum(1 for _ in csv.DictReader(f)) == count, topic


# ------------------------------------------------------------------------------ memory
def peak_rss_kib(*args: str) -> int:
    """
    Peak resident memory (KiB) of ``flexure-sim ARGS`` in a fresh interpreter.

    VmHWM of /proc/self/status (ru_maxrss would carry the peak of the forking test process over).
    """
    code = ("import contextlib, io, sys\n"
            "from flexure_sim import cli\n"
            "with contextlib.redirect_stdout(io.StringIO()), \\\n"
            "        contextlib.redirect_stderr(io.StringIO()):\n"
            "    rc = cli.main(sys.argv[1:])\n"
            "hwm = [l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM')][0]\n"
            "print(rc, hwm)\n")
    proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=600)
    rc, rss = proc.stdout.split()
    assert rc == "0", proc.stderr
    return int(rss)


@pytest.fixture(scope="module")
def long_runs(tmp_path_factory):
    """
    Return a run of the stage's topics and one ten times longer, both of several 256 KiB chunks.

    (paths, message counts).
    """
    root = tmp_path_factory.mktemp("long")
    short, long = root / "short.mcap", root / "long.mcap"
    counts = (record_long_run(short, 0.3, chunk_size=1 << 18),
              record_long_run(long, 3.0, chunk_size=1 << 18))
    return (short, long), counts


def test_analyse_and_info_keep_memory_bounded_on_a_ten_times_longer_recording(long_runs):
    """
    Streaming.

    The peak memory of analyse (and info) on a run 10 x longer stays within 1.2 x (the numeric
    series of the analysed topics grow, 8 bytes a value; no decoded messages are kept).
    """
    (short, long), (n_short, n_long) = long_runs
    assert n_long > 9 * n_short
    for tool in (("analyse", "--json"), ("info", "--json")):
        small = peak_rss_kib(tool[0], str(short), *tool[1:])
        large = peak_rss_kib(tool[0], str(long), *tool[1:])
        print(f"{tool[0]}: peak RSS {small} KiB ({n_short} messages), {large} KiB ({n_long})")
        assert large <= 1.2 * small, (tool, small, large)


def test_replay_reads_an_intact_file_in_log_time_order_in_bounded_memory(long_runs, tmp_path):
    """
    What replay plays.

    Every message of the chosen topics in log-time order (file order on ties), also when the file
    holds them out of order. Reading a run ten times longer adds to the peak of Python allocations
    less than a tenth of the payload bytes it adds (holding the payloads, as replay did, would add
    all of them; what grows is mcap's chunk index).
    """
    import tracemalloc

    from flexure_sim.recording.ordered import OrderedLog

    path = tmp_path / "shuffled.mcap"
    stamps = [5, 3, 3, 9, 1, 7, 3]
    with McapRecorder(path, chunk_size=64) as rec:
        rec.add_topic("/a", "std_msgs/msg/Float64")
        rec.add_topic("/b", "std_msgs/msg/Float64")
        for k, t in enumerate(stamps):
            rec.write("/a" if k % 2 else "/b", serialize_message(Float64(data=float(k))), t)
    for recover in (False, True):
        log = OrderedLog(path, recover=recover)
        played = [(t, topic, _float64(data)) for t, topic, data in log.messages(["/a", "/b"], 0)]
        expected = sorted(((t, "/a" if k % 2 else "/b", float(k)) for k, t in enumerate(stamps)),
                          key=lambda item: item[0])
        assert played == expected
        assert [_float64(d) for _, _, d in log.messages(["/a"], 4)] == [5.0, 3.0]
    peaks, payload = [], []
    for run in long_runs[0]:
        tracemalloc.start()
        log = OrderedLog(run)
        count = size = 0
        for _, _, data in log.messages(list(log.topics), log.start_ns):
            count, size = count + 1, size + len(data)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
        assert count == log.message_count
        payload.append(size)
    print(f"replay reading: peak Python allocations {peaks[0]} B, {peaks[1]} B; payloads "
          f"{payload[0]} B, {payload[1]} B")
    assert peaks[1] - peaks[0] < 0.1 * (payload[1] - payload[0]), (peaks, payload)


def _float64(data: bytes) -> float:
    return deserialize_message(data, Float64).data
