"""
One exception root.

Every error class of the package derives from FlexureSimError, and keeps its built-in base
(ValueError / RuntimeError) so existing handlers still catch it.
"""

import importlib
import inspect
import pkgutil

import numpy as np
import pytest

import flexure_sim
from flexure_sim.engine.kinematics import planar as kin
from flexure_sim.engine.fitting import datasets
from flexure_sim.engine.laws import monomials
from flexure_sim.engine.hinges import stiffness
from flexure_sim.errors import FlexureSimError


def _package_error_classes():
    """
    Return every error class defined in a module of the package (all modules imported).

    Errors derive from Exception; BaseException subclasses that are not Exceptions are control
    flow (as KeyboardInterrupt is: the node's Interrupted), not errors.
    """
    found = {}
    for info in pkgutil.walk_packages(flexure_sim.__path__, prefix="flexure_sim."):
        module = importlib.import_module(info.name)
        for _, obj in inspect.getmembers(module, inspect.isclass):
            if issubclass(obj, Exception) and obj.__module__ == module.__name__:
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


def test_every_package_error_derives_from_the_root():
    classes = _package_error_classes()
    # The walk must see the errors the package is known to raise (a guard against a walk
    # that silently imports nothing).
    expected = {
        "flexure_sim.engine.mechanism.values.ConfigError",
        "flexure_sim.engine.solver.model.SolverError",
        "flexure_sim.recording.exceptions.RecordingError",
        "flexure_sim.engine.fitting.wrench_data.DataError",
        "flexure_sim.engine.fitting.least_squares.FitError",
        "flexure_sim.engine.mechanism.polynomial_files.PolynomialFileError",
        "flexure_sim.recording.exceptions.RunError",
        "flexure_sim.cli.UsageError",
        "flexure_sim.node.apps.demo_drive.DriveError",
        "flexure_sim.node.stage.shell.StartupError",
    }
    assert expected <= set(classes), sorted(expected - set(classes))
    outside = sorted(name for name, cls in classes.items() if not issubclass(cls, FlexureSimError))
    assert not outside, f"error classes outside the FlexureSimError hierarchy: {outside}"


@pytest.mark.parametrize(
    "name,builtin",
    [
        ("flexure_sim.engine.mechanism.values.ConfigError", ValueError),
        ("flexure_sim.engine.mechanism.polynomial_files.PolynomialFileError", ValueError),
        ("flexure_sim.engine.fitting.wrench_data.DataError", ValueError),
        ("flexure_sim.engine.fitting.least_squares.FitError", ValueError),
        ("flexure_sim.cli.UsageError", ValueError),
        ("flexure_sim.engine.solver.model.SolverError", RuntimeError),
        ("flexure_sim.node.apps.demo_drive.DriveError", RuntimeError),
        ("flexure_sim.node.stage.stage_node.UsageError", ValueError),
        ("flexure_sim.node.stage.shell.StartupError", RuntimeError),
    ],
)
def test_errors_keep_their_builtin_base(name, builtin):
    module, _, cls = name.rpartition(".")
    error = getattr(importlib.import_module(module), cls)
    assert issubclass(error, builtin) and issubclass(error, FlexureSimError)
    with pytest.raises(FlexureSimError):
        raise error("x")


# ------------------------------------------------ argument checks name the argument


@pytest.mark.parametrize(
    "call,fragment",
    [
        (
            lambda: kin.twist_from_displacement(np.eye(3), [0.0, 0.0]),
            "R: expected shape (2, 2), got shape (3, 3)",
        ),
        (
            lambda: kin.twist_from_displacement(np.eye(2), [1.0, 2.0, 3.0]),
            "p: expected shape (2,), got shape (3,)",
        ),
        (
            lambda: kin.displacement_from_twist([0.1, 0.2]),
            "d: expected shape (3,), got shape (2,)",
        ),
        (
            lambda: kin.twistor_from_displacement(np.eye(2), np.zeros((2, 1))),
            "p: expected shape (2,)",
        ),
        (lambda: kin.twistor_from_twist(np.zeros(4)), "d: expected shape (3,)"),
        (lambda: kin.adjoint(np.eye(2), [0.0, 0.0, 0.0]), "p: expected shape (2,)"),
        (
            lambda: kin.transform_stiffness(np.eye(2), np.eye(2), [0.0, 0.0]),
            "K: expected shape (3, 3)",
        ),
        (lambda: kin.adjoint(np.eye(2), ["a", "b"]), "p: expected shape (2,), got ['a', 'b']"),
        (
            lambda: stiffness.notch_stiffness(np.array([0.003, 0.004]), 2.5e-4, 0.02, 69e9, 0.33),
            "D: expected a single number, got shape (2,)",
        ),
        (
            lambda: stiffness.cantilever_stiffness(0.01, 0.001, "wide", 69e9, 0.3),
            "width: expected a single number",
        ),
    ],
)
def test_argument_checks_name_the_argument(call, fragment):
    """
    Public functions name the argument and the expected shape.

    These used to fail in NumPy's matmul/broadcasting (or, for a 3x3 R, silently returned a
    wrong twist).
    """
    with pytest.raises(ValueError) as err:
        call()
    assert str(err.value).startswith(fragment), str(err.value)


@pytest.mark.parametrize(
    "call,fragment",
    [
        (
            lambda: monomials.monomials(np.zeros((2, 3)), np.zeros((5, 4))),
            "exponents: expected shape (n, 3)",
        ),
        (
            lambda: monomials.monomial_gradients(np.zeros(3), np.zeros((5, 3))),
            "u: expected shape (n, n)",
        ),
        (
            lambda: monomials.compose_linear(np.zeros(15), 4, 2, np.eye(3)),
            "M: expected shape (4, 4)",
        ),
        (
            lambda: monomials.compose_linear(np.zeros(14), 4, 2, np.eye(4)),
            "coefficients: expected shape (15,)",
        ),
        (
            lambda: monomials.derivative_coefficients(np.zeros(3), 4, 2, 0),
            "coefficients: expected shape (15,)",
        ),
        (
            lambda: datasets.sample_box(3, 0.1, [1e-6, 1e-6, 1e-6], np.random.default_rng(0)),
            "p_max: expected shape (2,)",
        ),
        (
            lambda: datasets.leaf_tip(datasets.Leaf(), np.zeros((2, 3)), np.zeros(2)),
            "force: expected shape (n, 2)",
        ),
    ],
    ids=[
        "monomials",
        "monomial_gradients",
        "compose_linear M",
        "compose_linear coefficients",
        "derivative_coefficients",
        "sample_box",
        "leaf_tip",
    ],
)
def test_polynomial_and_data_set_helpers_name_the_argument(call, fragment):
    with pytest.raises(ValueError) as err:
        call()
    assert str(err.value).startswith(fragment), str(err.value)
