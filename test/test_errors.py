"""One exception root: every error class of the package derives from FlexureSimError, and
keeps its built-in base (ValueError / RuntimeError) so existing handlers still catch it."""
import importlib
import inspect
import pkgutil

import pytest

import flexure_sim
from flexure_sim.errors import FlexureSimError


def _package_error_classes():
    """Every exception class defined in a module of the package (all modules imported)."""
    found = {}
    for info in pkgutil.walk_packages(flexure_sim.__path__, prefix="flexure_sim."):
        module = importlib.import_module(info.name)
        for _, obj in inspect.getmembers(module, inspect.isclass):
            if issubclass(obj, BaseException) and obj.__module__ == module.__name__:
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


def test_every_package_error_derives_from_the_root():
    classes = _package_error_classes()
    # The walk must see the errors the package is known to raise (a guard against a walk
    # that silently imports nothing).
    expected = {
        "flexure_sim.engine.config.ConfigError", "flexure_sim.engine.solver.SolverError",
        "flexure_sim.recording.errors.RecordingError", "flexure_sim.engine.fitting.DataError",
        "flexure_sim.engine.fitting.FitError", "flexure_sim.engine.polynomial.PolynomialFileError",
        "flexure_sim.tools.runlog.RunError", "flexure_sim.cli.UsageError",
        "flexure_sim.node.demo_drive.DriveError", "flexure_sim.node.stage_node.StartupError",
    }
    assert expected <= set(classes), sorted(expected - set(classes))
    outside = sorted(name for name, cls in classes.items() if not issubclass(cls, FlexureSimError))
    assert not outside, f"error classes outside the FlexureSimError hierarchy: {outside}"


@pytest.mark.parametrize("name,builtin", [
    ("flexure_sim.engine.config.ConfigError", ValueError),
    ("flexure_sim.engine.polynomial.PolynomialFileError", ValueError),
    ("flexure_sim.engine.fitting.DataError", ValueError),
    ("flexure_sim.engine.fitting.FitError", ValueError),
    ("flexure_sim.cli.UsageError", ValueError),
    ("flexure_sim.engine.solver.SolverError", RuntimeError),
    ("flexure_sim.node.demo_drive.DriveError", RuntimeError),
    ("flexure_sim.node.stage_node.StartupError", RuntimeError),
])
def test_errors_keep_their_builtin_base(name, builtin):
    module, _, cls = name.rpartition(".")
    error = getattr(importlib.import_module(module), cls)
    assert issubclass(error, builtin) and issubclass(error, FlexureSimError)
    with pytest.raises(FlexureSimError):
        raise error("x")
