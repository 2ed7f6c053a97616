"""
The Model's shape a newcomer reads (issue 26 item 4).

A drive table held by the Model (``model.drives``) instead of attributes a mixin injects; one
return type per derivative function (``jacobian``: A; ``tangent``: a ``Tangent``); a state's u
and commands always arrays; no private attribute of another object read by the Model.
"""
import ast
import inspect

import numpy as np
import pytest

from flexure_sim.engine.mechanism.loader import load_mechanism, mechanism_from_dict
from flexure_sim.engine.solver import model as model_module
from flexure_sim.engine.solver import step_energy
from flexure_sim.engine.solver.drives import DriveTable
from flexure_sim.engine.solver.derivatives import Tangent
from flexure_sim.engine.solver.simulation import Simulation


def _moving(name: str, command):
    """Return a simulation of ``name`` a few steps after a command step (v_P, v_F not zero)."""
    sim = Simulation(load_mechanism(name))
    sim.set_command(command)
    sim.step(3)
    return sim


@pytest.mark.parametrize("name, command", [("microstage", 1.35e-6),
                                           ("xy_stage", {"x": 1e-6, "y": 4e-6})])
def test_jacobian_is_one_matrix_and_tangent_one_record(name, command):
    """
    ``jacobian`` returns A; ``tangent`` its A (the same bits) and the drive loads' gradient.

    G = dq/dy of each drive's load q_d = D_d^T Q_P is checked against central differences of
    the loads the right-hand side reports (``step_energy.AUX_LOAD``), a second method.
    """
    sim = _moving(name, command)
    model = sim.model
    y, t = model.pack(sim.state), sim.state.t
    command = model.drives.kernel_command(sim.state.command)
    A = model.jacobian(y, t, command)
    tangent = model.tangent(y, t, command)
    assert isinstance(A, np.ndarray) and A.shape == (len(y), len(y))
    assert isinstance(tangent, Tangent)
    assert np.array_equal(tangent.A, A)
    nd = model.drives.n_lags
    assert tangent.G.shape == (nd, len(y))

    def loads(yy):
        return model.rhs_python(yy, t, command)[1][step_energy.AUX_LOAD:]

    fd = np.empty((nd, len(y)))
    for j in range(len(y)):
        h = 1e-6 * max(abs(y[j]), 1e-9)
        yp, ym = y.copy(), y.copy()
        yp[j] += h
        ym[j] -= h
        fd[:, j] = (loads(yp) - loads(ym)) / (2 * h)
    np.testing.assert_allclose(tangent.G, fd, rtol=0, atol=1e-5 * np.abs(tangent.G).max())


def test_the_state_holds_u_and_commands_as_arrays_for_any_number_of_drives():
    """One drive, two drives, none: u and command are arrays, stepped or solved statically."""
    one = _moving("microstage", 1.35e-6)
    assert one.state.u.shape == (1,) and one.state.command.shape == (1,)
    assert one.state.command[0] == 1.35e-6
    two = _moving("xy_stage", {"x": 1e-6, "y": 4e-6})
    assert two.state.u.shape == (2,)
    np.testing.assert_array_equal(two.state.command, [1e-6, 4e-6])
    static = Simulation(load_mechanism("microstage")).static(1.35e-6)
    assert static.snapshot.drive_commands.shape == (1,)
    none = Simulation(load_mechanism("fourbar_mixed"))
    none.step(2)
    assert none.state.u.shape == (0,) and none.state.command.shape == (0,)
    copy = one.state.copy()
    copy.u[0] = 0.0
    assert one.state.u[0] != 0.0     # a copy owns its arrays


def test_a_state_of_the_wrong_size_is_refused_by_name():
    sim = Simulation(load_mechanism("xy_stage"))
    state = sim.state.copy()
    state.u = np.zeros(1)
    with pytest.raises(ValueError, match="u has 1 entries.*2 displacement drives"):
        sim.model.pack(state)
    with pytest.raises(TypeError, match="kernel's command vector"):
        sim.model.rhs(sim.model.pack(sim.state), 0.0, 1e-6)


def test_the_model_holds_its_drives_in_a_table_by_kind():
    """
    Displacement, force and stack drives of one mechanism, each in its index array.

    The kernel's command vector holds the displacement drives' commands, then the forces, in
    the table's ``order``; the Model itself carries no per-drive arrays of its own.
    """
    mech = mechanism_from_dict({
        "name": "rotor2", "defaults": {"law": "twistor", "damping": {"t_char": 1e-3}},
        "bodies": [{"name": "base", "mass": 1.0, "inertia": 1.0, "pose": [0, 0, 0]},
                   {"name": "disc", "mass": 0.01, "inertia": 1e-6, "pose": [0.01, 0, 0]}],
        "hinges": [{"name": "h", "a": {"body": "base", "at": [0.01, 0]},
                    "b": {"body": "disc", "at": [0, 0]},
                    "stiffness": {"model": "matrix", "Ko": 2.5, "Kt": [1e7, 2e6]}}],
        "constraints": [{"type": "fixed", "body": "base"},
                        {"type": "force", "name": "torquer", "body": "disc", "axis": "theta",
                         "response_time": 1e-3, "stroke": [-1, 1], "slew_rate": 1.0},
                        {"type": "drive", "name": "push", "body": "disc", "axis": "x",
                         "response_time": 2e-3, "stroke": [-1e-5, 1e-5], "slew_rate": 1.0}]})
    model = Simulation(mech).model
    drives = model.drives
    assert isinstance(drives, DriveTable)
    assert drives.names == ("torquer", "push")
    assert [d.name for d in drives] == ["torquer", "push"]
    assert list(drives.displacement) == [1] and list(drives.force) == [0]
    assert len(drives.stack) == 0 and drives.n_lags == 1
    np.testing.assert_array_equal(drives.tau, [2e-3])
    np.testing.assert_array_equal(drives.kernel_command(np.array([3.0, 4e-6])), [4e-6, 3.0])
    for name in ("tau", "D_rows", "force_dir", "stack_K", "actuation", "drive_names",
                 "displacement_index", "drive_inputs", "actuator_command"):
        assert not hasattr(model, name), name


def test_the_model_reads_no_private_attribute_of_another_object():
    """An AST scan of model.py: every ``x._name`` it reads has x = self."""
    tree = ast.parse(inspect.getsource(model_module))
    foreign = sorted({f"{ast.unparse(node.value)}.{node.attr}" for node in ast.walk(tree)
                      if isinstance(node, ast.Attribute) and node.attr.startswith("_")
                      and not node.attr.startswith("__")
                      and not (isinstance(node.value, ast.Name) and node.value.id == "self")})
    assert not foreign, f"model.py reads private attributes of other objects: {foreign}"
