"""
Bad fit inputs end in one message naming the file (and line/column), never a traceback.

Issue 16 item 12: ``flexure-sim fit`` on a CSV holding 1e300 values, binary garbage or a
Latin-1 comment line. Also fuzzed (hypothesis, derandomized and bounded): the CSV reader and
the polynomial hinge file loader raise only their own errors (DataError, PolynomialFileError).
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import ROOT
from flexure_sim.engine.fitting.least_squares import FitError, fit_polynomial
from flexure_sim.engine.mechanism.polynomial_files import PolynomialFileError, load_law
from flexure_sim.engine.fitting.wrench_data import (
    MAX_ABS_VALUE, DataError, WrenchData, read_wrench_csv,
)

EXAMPLES = ROOT / "config" / "examples"
TRAIN = (EXAMPLES / "notch_hinge_train.csv").read_text()
LAW_TEXT = (EXAMPLES / "notch_hinge_order4.yaml").read_text()


def _row(text: str, index: int) -> list[str]:
    """Return data row `index` (0-based) of a CSV text without comments, as its fields."""
    rows = [line for line in text.splitlines() if line and not line.startswith("#")]
    return rows[1 + index].split(",")


def _with_row(text: str, index: int, fields: list[str]) -> str:
    lines = text.splitlines()
    data = [i for i, line in enumerate(lines) if line and not line.startswith("#")][1:]
    lines[data[index]] = ",".join(fields)
    return "\n".join(lines) + "\n"


def _bad_files(directory):
    """
    Return the issue's three files (plus a NUL byte).

    They are returned as name -> (path, fragments of the message).
    """
    header = TRAIN.splitlines()
    lines = [line for line in header if line and not line.startswith("#")]
    columns = lines[0].split(",")
    fields = _row(TRAIN, 4)
    fields[columns.index("fx")] = "1e300"
    huge = _with_row(TRAIN, 4, fields)
    lineno = huge.splitlines().index(",".join(fields)) + 1
    files = {
        "huge.csv": (huge.encode(), [f"line {lineno}, column 'fx'", "1e+300 is out of range"]),
        "garbage.csv": (
            bytes(range(255, -1, -1)) * 8,
            ["a binary file, not text", "line 1, column 1"],
        ),
        "latin1.csv": (
            "# mesuré au banc\n".encode("latin-1") + TRAIN.encode(),
            ["not UTF-8 text", "byte 0xe9 at line 1, column 8"],
        ),
        "nul.csv": (TRAIN.replace("\n", "\n\0", 3).encode(), ["contains a NUL byte"]),
    }
    out = {}
    for name, (content, fragments) in files.items():
        path = directory / name
        path.write_bytes(content)
        out[name] = (path, fragments)
    return out


def test_the_reader_names_file_line_and_column(tmp_path):
    for name, (path, fragments) in _bad_files(tmp_path).items():
        with pytest.raises(DataError) as err:
            read_wrench_csv(path)
        msg = str(err.value)
        assert msg.startswith(f"{path}: ") and "\n" not in msg, msg
        for fragment in fragments:
            assert fragment in msg, (name, msg)


def test_fit_command_exits_2_with_one_line(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for name, (path, fragments) in _bad_files(tmp_path).items():
        p = subprocess.run(
            [sys.executable, "-m", "flexure_sim.cli", "fit", str(path), "--order", "2"],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
        )
        assert p.returncode == 2, (name, p.stderr)
        assert "Traceback" not in p.stderr and p.stdout == ""
        lines = p.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(
            f"flexure-sim fit: error: {path}: "
        ), p.stderr
        for fragment in fragments:
            assert fragment in lines[0], lines[0]


def test_fit_refuses_values_that_overflow_its_arithmetic():
    """
    Data built in memory (no CSV) with 1e300 wrenches.

    The squares overflow, so the fit says which value is too large instead of failing in the SVD.
    """
    rng = np.random.default_rng(3)
    n = 30
    wrench = rng.normal(size=(n, 3))
    wrench[7, 2] = 1e300
    data = WrenchData(rng.uniform(-0.01, 0.01, n), rng.normal(size=(n, 2)) * 1e-5, wrench, "bench")
    with pytest.raises(FitError, match=r"^bench: row 8, column 'fy': 1e\+300 is too large to fit"):
        fit_polynomial(data, 2)
    assert (
        MAX_ABS_VALUE**2 * 3 < np.finfo(float).max
    )  # sums of squares of accepted values stay finite


@pytest.mark.parametrize(
    "alpha,p,wrench,name",
    [
        (np.zeros(3), np.zeros((3, 3)), np.zeros((3, 3)), "p"),
        (np.zeros(3), np.zeros((3, 2)), np.zeros(9), "wrench"),
        (np.zeros((3, 1)), np.zeros((3, 2)), np.zeros((3, 3)), "alpha"),
        (np.zeros(3), [["a", "b"]] * 3, np.zeros((3, 3)), "p"),
    ],
)
def test_wrench_data_names_the_argument_of_the_wrong_shape(alpha, p, wrench, name):
    with pytest.raises(ValueError, match=rf"^{name}: expected"):
        WrenchData(alpha, p, wrench)


# ------------------------------------------------------------------------- fuzzing

FUZZ = settings(
    max_examples=100,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
CELLS = st.one_of(
    st.text(max_size=8),
    st.sampled_from(["1e300", "-1e300", "nan", "inf", "1e151", "3.2", "", '"', "1,2"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
)


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fitfuzz")


def _read_or_data_error(path):
    try:
        data = read_wrench_csv(path)
    except DataError as exc:
        assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc), str(exc)
        return
    table = np.column_stack([data.alpha, data.p, data.wrench])
    assert np.all(np.isfinite(table)) and np.max(np.abs(table)) <= MAX_ABS_VALUE


@FUZZ
@given(row=st.integers(0, 20), column=st.integers(0, 5), cell=CELLS)
def test_fuzz_csv_cells(fuzz_dir, row, column, cell):
    fields = _row(TRAIN, row)
    fields[column] = cell
    path = fuzz_dir / "cells.csv"
    path.write_text(_with_row(TRAIN, row, fields), encoding="utf-8")
    _read_or_data_error(path)


@FUZZ
@given(at=st.integers(0, 2000), junk=st.binary(min_size=1, max_size=16))
def test_fuzz_csv_bytes(fuzz_dir, at, junk):
    raw = TRAIN.encode()
    path = fuzz_dir / "bytes.csv"
    path.write_bytes(raw[:at] + junk + raw[at:])
    _read_or_data_error(path)


LAW = yaml.safe_load(LAW_TEXT)
DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
LAW_KEYS = [
    "format",
    "version",
    "coordinates",
    "variables",
    "order",
    "rest",
    "scale",
    "energy",
    "terms",
]
VALUES = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8)
    | st.sampled_from([10**400, "twist", "twistor", [1.0, 0.0, 0.0, 0.0], 1e-300]),
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.text(max_size=6), children, max_size=3),
    max_leaves=8,
)


@settings(FUZZ, max_examples=60)  # each example parses a 2 kB YAML file (pure-Python PyYAML)
@given(key=st.sampled_from(LAW_KEYS), value=VALUES, term=st.integers(0, 5), in_term=st.booleans())
def test_fuzz_polynomial_files(fuzz_dir, key, value, term, in_term):
    doc = yaml.safe_load(LAW_TEXT)
    if in_term:  # a value inside one term
        doc["terms"][term][["exponents", "coefficient"][term % 2]] = value
    else:
        doc[key] = value
    path = fuzz_dir / "law.yaml"
    path.write_text(
        yaml.dump(doc, Dumper=DUMPER, sort_keys=False, allow_unicode=True), encoding="utf-8"
    )
    try:
        load_law(path)
    except PolynomialFileError as exc:
        assert str(exc).startswith(f"{path}: ") and "\n" not in str(exc), str(exc)


@pytest.mark.parametrize(
    "key,value,fragment",
    [
        ("coordinates", ["twist"], "coordinates: expected one of twistor, twist, got ['twist']"),
        ("variables", 3, "variables: expected"),
        ("energy", 10**400, "energy: expected a finite number, got 1000"),
        ("scale", [1, 1, 10**400, 1], "scale[2]: expected a finite number"),
    ],
    ids=["coordinates", "variables", "energy", "scale"],
)
def test_polynomial_file_problems_name_the_key(tmp_path, key, value, fragment):
    doc = dict(LAW, **{key: value})
    path = tmp_path / "law.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    with pytest.raises(PolynomialFileError) as err:
        load_law(path)
    assert str(err.value).startswith(f"{path}: {fragment}"), str(err.value)
