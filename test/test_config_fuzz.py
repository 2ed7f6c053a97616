"""
Bad mechanism files end in one ConfigError line (file: key: problem), never a traceback.

The four files of issue 16 item 6 (binary garbage, a Latin-1 comment, unhashable values) are
checked one by one, through the loader, ``flexure-sim simulate`` (exit 2) and ``stage_node``
(exit 1). Then the loader is fuzzed with hypothesis: the shipped microstage.yaml with a value
at a random path replaced by a random YAML value (None, booleans, huge integers, NaN, inf,
strings, lists, mappings) or removed, and random bytes. The examples are derandomized and
bounded, so the suite stays deterministic and quick. Whatever loads must be physically
meaningful (finite positive masses, finite positive-definite stiffness...).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flexure_sim.engine.mechanism.loader import ConfigError, load_mechanism, resolve_mechanism_path
from flexure_sim.engine.mechanism.parts import Mechanism

from conftest import ROOT

STAGE_TEXT = resolve_mechanism_path("microstage").read_text()
STAGE = yaml.safe_load(STAGE_TEXT)
#: libyaml's dumper when present: the fuzz examples are written quickly (the loader under test
#: is the package's own).
DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)

#: The files of the issue: name -> (content, a fragment the message must hold).
ISSUE_FILES = {
    "garbage": (bytes(range(256)) * 8, "binary file"),
    "latin1": (
        "# réglage du moteur\n".encode("latin-1") + STAGE_TEXT.encode(),
        "byte 0xe9 at line 1, column 4",
    ),
    "compression": (
        STAGE_TEXT.replace("compression_hinge: a", "compression_hinge: [a]").encode(),
        "compression_hinge: expected a hinge name, got ['a']",
    ),
    "output_body": (
        STAGE_TEXT.replace("output: {body: body4,", "output: {body: [body4],").encode(),
        "output.body: expected a body name",
    ),
    "stiffness_model": (
        STAGE_TEXT.replace("{model: notch,", "{model: [notch],").encode(),
        "stiffness_models.notch.model: expected a model name",
    ),
    "constraint_body": (
        STAGE_TEXT.replace("{type: fixed, body: body1}", "{type: fixed, body: [body1]}").encode(),
        "constraints[0].body: expected a body name",
    ),
}


def _write(directory: Path, name: str, content: bytes) -> Path:
    path = directory / f"{name}.yaml"
    path.write_bytes(content)
    return path


def _expect_one_line(path: Path, *fragments: str) -> str:
    with pytest.raises(ConfigError) as err:
        load_mechanism(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: ") and "\n" not in msg, msg
    for fragment in fragments:
        assert fragment in msg, msg
    return msg


def test_the_issue_files_are_rejected_with_file_key_and_problem(tmp_path):
    for name, (content, fragment) in ISSUE_FILES.items():
        assert content != STAGE_TEXT.encode(), name  # the edit took place
        _expect_one_line(_write(tmp_path, name, content), fragment)


def _mutated(*changes) -> dict:
    """Return the stage document with values replaced: changes are (path, value) pairs."""
    doc = yaml.safe_load(STAGE_TEXT)
    for path, value in changes:
        node = doc
        for step in path[:-1]:
            node = node[step]
        node[path[-1]] = value
    return doc


@pytest.mark.parametrize(
    "changes,fragments",
    [
        ([(("bodies", 2, "mass"), float("nan"))], ("bodies[2].mass", "must be finite")),
        ([(("bodies", 2, "inertia"), float("inf"))], ("bodies[2].inertia", "must be finite")),
        ([(("bodies", 1, "mass"), 10**400)], ("bodies[1].mass", "must be finite")),
        (
            [(("stiffness_models", "notch", "t"), -0.02)],
            ("stiffness_models.notch.t", "must be positive"),
        ),
        (
            [(("stiffness_models", "notch", "E"), float("inf"))],
            ("stiffness_models.notch.E", "must be finite"),
        ),
        # Each number is finite, but the formula overflows: E t h^2 with E = t = 1e300.
        (
            [
                (
                    ("stiffness_models", "notch"),
                    {
                        "model": "notch",
                        "D": 0.003,
                        "h": 0.00025,
                        "t": 1e300,
                        "E": 1e300,
                        "nu": 0.3,
                    },
                )
            ],
            ("stiffness_models.notch", "non-finite stiffness"),
        ),
        (
            [
                (
                    ("hinges", 0, "stiffness"),
                    {"model": "matrix", "Ko": 1e308, "Kt": [1e308, 1e308], "Kc": [1e308, 1e308]},
                )
            ],
            ("hinges[0].stiffness", "not positive definite"),
        ),
        (
            [(("hinges", 0, "damping"), {"t_char": 1e305})],
            ("hinges[0].damping.t_char", "not finite"),
        ),
        # Body pose plus frame position overflow: the coincidence test must not pass on NaN.
        (
            [
                (("bodies", 0, "pose"), [1e308, 0.0, 0.0]),
                (("hinges", 1, "a", "at"), [1e308, 0.044]),
            ],
            ("hinges[1]", "not finite"),
        ),
        ([(("hinges", 1, "law"), [1, 2])], ("hinges[1].law", "unknown law [1, 2]")),
        (
            [(("hinges", 1, "law"), {"polynomial": "a\0b"})],
            ("hinges[1].law.polynomial", "expected the path"),
        ),
        ([(("bodies", 0, "name"), "bödy")], ("bodies[0].name", "not a valid name")),
        (
            [(("bodies", 0), {"name": "body1", 1: 2, "x": 3, "mass": 1.0, "inertia": 1.0})],
            ("bodies[0].1", "unknown key"),
        ),
        (
            [(("constraints", 0, "type"), {"a": [1]})],
            ("constraints[0].type", "unknown constraint type {'a': [1]}"),
        ),
    ],
)
def test_semantic_problems_name_the_key(tmp_path, changes, fragments):
    file = _write(tmp_path, "bad", yaml.safe_dump(_mutated(*changes), sort_keys=False).encode())
    _expect_one_line(file, *fragments)


def test_an_axis_near_the_double_range_is_normalised(tmp_path):
    doc = _mutated((("constraints", 1, "axis"), [1e308, 1e308]))
    mech = load_mechanism(_write(tmp_path, "axis", yaml.safe_dump(doc, sort_keys=False).encode()))
    assert mech.drive.axis == pytest.approx((math.sqrt(0.5), math.sqrt(0.5)), rel=1e-15)


@pytest.mark.parametrize(
    "text,fragment",
    [
        ("a: 2024-13-01\n", "a value cannot be read: month must be in 1..12"),
        ("a: [\n  b: 1\n", "line 3, column 1"),
        ("name: x\x01\n", "line 1, column 8: character #x0001"),
        ("a: " + "[" * 1000 + "]" * 1000 + "\n", "nested too deeply"),
    ],
)
def test_yaml_errors_are_one_line(tmp_path, text, fragment):
    _expect_one_line(_write(tmp_path, "bad", text.encode()), "not valid YAML", fragment)


# ------------------------------------------------------------------------- fuzzing


def _paths(node, prefix=()):
    """Every path (keys and indices) into the document, the document itself first."""
    yield prefix
    items = (
        node.items()
        if isinstance(node, dict)
        else enumerate(node) if isinstance(node, list) else ()
    )
    for key, child in items:
        yield from _paths(child, prefix + (key,))


PATHS = list(_paths(STAGE))[1:]

#: Values that mean something to the loader, so that mutations also reach its deeper checks.
MEANINGFUL = st.sampled_from(
    [
        "body1",
        "body4",
        "a",
        "notch",
        "twistor",
        "twist",
        "fixed",
        "drive",
        "sine_rate",
        "theta",
        "matrix",
        "69.0e9",
        "nan",
        "-inf",
        "",
        0,
        -1,
        1e-300,
        5e-324,
        1e308,
        -1e308,
        10**400,
        [0.0, 0.0],
        [1.0, 0.0, 0.0],
        [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        {"model": "matrix"},
        {"t_char": 1e-3},
        {"polynomial": "absent.yaml"},
    ]
)
SCALARS = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=12)
    | MEANINGFUL
)
VALUES = st.recursive(
    SCALARS,
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.text(max_size=8) | st.integers(), children, max_size=4),
    max_leaves=12,
)
FUZZ = settings(
    max_examples=120,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


def _load_or_config_error(path: Path):
    """Return the loader's only outcomes: a meaningful mechanism, or one ConfigError line."""
    try:
        mech = load_mechanism(path)
    except ConfigError as exc:
        msg = str(exc)
        assert msg.startswith(f"{path}: ") and "\n" not in msg, msg
        return None
    _check_meaningful(mech)
    return mech


def _check_meaningful(mech: Mechanism) -> None:
    for body in mech.bodies:
        assert (
            math.isfinite(body.mass)
            and body.mass > 0
            and math.isfinite(body.inertia)
            and body.inertia > 0
        )
        assert all(math.isfinite(v) for v in body.pose)
    for hinge in mech.hinges:
        assert np.all(np.isfinite(hinge.law.K)) and np.all(
            np.linalg.eigvalsh(hinge.law.K) > 0
        ), hinge.name
        assert np.all(np.isfinite(hinge.law.B)) and np.all(
            np.linalg.eigvalsh(hinge.law.B) >= -1e-12 * np.abs(hinge.law.B).max()
        )
    if mech.drive is not None:
        assert math.hypot(*mech.drive.axis) == pytest.approx(1.0, rel=1e-12)
        assert mech.drive.stroke[0] < mech.drive.stroke[1]


@FUZZ
@given(path=st.sampled_from(PATHS), value=VALUES, delete=st.booleans())
def test_fuzz_values_at_random_paths(fuzz_dir, path, value, delete):
    doc = yaml.safe_load(STAGE_TEXT)
    parent = doc
    for step in path[:-1]:
        parent = parent[step]
    if delete:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    file = fuzz_dir / "mutated.yaml"
    text = yaml.dump(doc, Dumper=DUMPER, sort_keys=False, allow_unicode=True)
    file.write_text(text, encoding="utf-8")
    _load_or_config_error(file)


@FUZZ
@given(data=st.binary(max_size=2048))
def test_fuzz_random_bytes(fuzz_dir, data):
    file = fuzz_dir / "random.yaml"
    file.write_bytes(data)
    _load_or_config_error(file)


@FUZZ
@given(at=st.integers(0, len(STAGE_TEXT.encode())), junk=st.binary(min_size=1, max_size=16))
def test_fuzz_bytes_spliced_into_the_stage(fuzz_dir, at, junk):
    raw = STAGE_TEXT.encode()
    file = fuzz_dir / "spliced.yaml"
    file.write_bytes(raw[:at] + junk + raw[at:])
    _load_or_config_error(file)


# ------------------------------------------------------------------ the two programs


@pytest.fixture(scope="module")
def issue_files(tmp_path_factory):
    directory = tmp_path_factory.mktemp("issue16")
    return {
        name: (_write(directory, name, content), fragment)
        for name, (content, fragment) in ISSUE_FILES.items()
    }


@pytest.mark.slow
def test_simulate_reports_bad_files_in_one_line_with_exit_2(issue_files):
    for name, (path, fragment) in issue_files.items():
        p = subprocess.run(
            [
                sys.executable,
                "-m",
                "flexure_sim.cli",
                "simulate",
                str(path),
                "--duration",
                "0.001",
            ],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert p.returncode == 2, (name, p.stderr)
        assert "Traceback" not in p.stderr and p.stdout == ""
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"flexure-sim: error: {path}: "), p.stderr
        assert fragment in lines[0], lines[0]


@pytest.mark.slow
def test_stage_node_reports_bad_files_with_exit_1(issue_files, tmp_path):
    """The installed console script, as a user starts it (scripts/venv.sh installs it)."""
    exe = Path(sys.prefix) / "bin" / "stage_node"
    env = dict(
        os.environ,
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        ROS_LOG_DIR=str(tmp_path / "ros_log"),
        ROS_DOMAIN_ID=os.environ.get("ROS_DOMAIN_ID", "0"),
    )
    for name, (path, fragment) in issue_files.items():
        p = subprocess.run(
            [str(exe), "--ros-args", "-p", f"mechanism:={path}"],
            env=env,
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert p.returncode == 1, (name, p.stderr)
        assert "Traceback" not in p.stderr
        assert f"stage_node: error: {path}: " in p.stderr and fragment in p.stderr, p.stderr
