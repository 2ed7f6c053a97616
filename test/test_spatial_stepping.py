"""
Stepping spatial mechanisms: the compiled kernel, the exact Jacobian, and the motion.

References: the interpreted (Python) binding of the same force chain (the compiled one must
agree to rounding), central differences of F(y) for its Jacobian, and for the motion the
exact response of the linear model computed with SciPy's matrix exponential, and the static
equilibrium the motion settles into.
"""
import numpy as np
import pytest
import scipy.linalg

from flexure_sim.engine.analysis import spatial_linear
from flexure_sim.engine.kinematics import scalar
from flexure_sim.engine.mechanism.spatial_loader import load_spatial
from flexure_sim.engine.solver import spatial_chain
from flexure_sim.engine.solver.spatial_model import SpatialModel
from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation
from flexure_sim.engine.solver.spatial_statics import static_gain

RNG = np.random.default_rng(7)


def disturbed(model):
    """Return a state a little away from rest: mm and degree offsets, random rates."""
    nF = len(model.part.free)
    rot = model.part.free % 6 >= 3
    zF = model.z0[model.part.free] + np.where(rot, 0.02, 2e-5) * RNG.normal(size=nF)
    wF = np.where(rot, 5.0, 5e-3) * RNG.normal(size=nF)
    return np.concatenate([zF, wF, 1e-6 * RNG.random(model.n_actuators)])


@pytest.mark.parametrize("name", ["tiptilt_stage", "microstage"])
def test_compiled_and_python_evaluations_agree(name):
    model = SpatialModel(load_spatial(name))
    y = disturbed(model)
    z, w, _ = model.unpack(y, 0.0, 0.0)
    command = model.kernel_command(np.full(len(model.drives), 1e-6))
    compiled = model.terms(z, w, command)
    nh, N = len(model.mechanism.hinges), model.n_coordinates
    out = [scalar.zeros(N), scalar.zeros(N), scalar.zeros((nh, 6)), scalar.zeros((nh, 6)),
           scalar.zeros((nh, 3))]
    energy, dissipation = spatial_chain.terms(z, w, command, model.first_force, model.constants,
                                              *out, True)
    for got, ref in zip(out, compiled[:5]):
        got = np.asarray(got, dtype=float)
        assert np.allclose(got, ref, rtol=1e-13, atol=1e-13 * np.abs(ref).max())
    assert energy == pytest.approx(compiled[5], rel=1e-13)
    assert dissipation == pytest.approx(compiled[6], rel=1e-13)


@pytest.mark.parametrize("name", ["tiptilt_stage", "microstage"])
def test_jacobian_is_the_derivative_of_the_kernel(name):
    model = SpatialModel(load_spatial(name))
    y = disturbed(model)
    command = np.full(len(model.drives), 1e-6)
    A = model.jacobian(y, 0.0, command)
    fd = np.empty_like(A)
    for j in range(len(y)):
        h = 1e-6 * max(abs(y[j]), 1e-3 if j < len(model.part.free) else 1e-2)
        up, down = y.copy(), y.copy()
        up[j] += h
        down[j] -= h
        fd[:, j] = (model.rhs(up, 0.0, command)[0] - model.rhs(down, 0.0, command)[0]) / (2 * h)
    scale = np.abs(fd).max(axis=1, keepdims=True)
    assert np.all(np.abs(A - fd) <= 1e-5 * scale + 1e-9)


def test_tiptilt_follows_its_exact_linear_model_and_settles_at_its_static_gain():
    """A 1 nm step of stack 1: the stepped tip and piston against C (e^{At} - I) A^-1 B u."""
    sim = SpatialSimulation(load_spatial("tiptilt_stage"), dt=2e-5)
    lin = spatial_linear.linearize(sim.model, wrenches=False)
    u = np.array([1e-9, 0.0, 0.0])
    sim.set_command(u)
    rows = [lin.output_index(n) for n in ("tip", "tilt", "piston")]
    for k in range(1, 16):
        sim.step(20)
        t = sim.state.t
        grow = scipy.linalg.expm(lin.A * t) - np.eye(len(lin.A))
        x = np.linalg.solve(lin.A, grow @ lin.B @ u)
        expected = lin.C[rows] @ x
        got = np.array([sim.snapshot().outputs[n] for n in ("tip", "tilt", "piston")])
        assert np.allclose(got, expected, rtol=0, atol=1e-6 * np.abs(expected).max())
    sim.step(3000)
    settled = sim.model.output_values(sim.static(u).z)
    got = np.array([sim.snapshot().outputs[n] for n in ("tip", "tilt", "piston")])
    # (rounding: deflections are differences of positions ~1.5e-2 m, 3e-18 m apart)
    assert np.allclose(got, settled, rtol=0, atol=1e-6 * np.abs(settled).max())
    gain = static_gain(sim.model) @ u
    assert np.allclose(got, gain, rtol=0, atol=1e-6 * np.abs(gain).max())
    assert sim.stats.linearizations == 1


@pytest.mark.parametrize("name", ["tiptilt_stage", "microstage"])
def test_complex_step_and_hyper_dual_derivatives_agree(name):
    """Two bindings of one chain: the compiled complex step against interpreted hyper-duals."""
    model = SpatialModel(load_spatial(name))
    y = disturbed(model)
    command = model.kernel_command(np.full(len(model.drives), 1e-6))
    z, w, _ = model.unpack(y, 0.0, command)
    Zx, Wx = model.seeds(n_extra=len(command))
    Cx = np.zeros((len(command), Zx.shape[1]))
    Cx[:, -len(command):] = np.eye(len(command))
    for got, ref in zip(model.derivatives(z, w, command, Zx, Wx, Cx),
                        model.derivatives_hyperdual(z, w, command, Zx, Wx, Cx)):
        assert np.allclose(got, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


@pytest.mark.slow
def test_the_benchmarked_3d_stage_steps_at_the_planar_accuracy():
    """
    The accuracy claims behind ``flexure-sim bench``'s 3-D figures (speed is printed only).

    The stage in 3-D and the planar stage at the shipped step: the same output error against
    each engine's own converged reference, nothing out of the plane; the tip-tilt stage's tip
    within 1e-4 of its reference.
    """
    from flexure_sim.tools.bench.spatial_bench import bench_spatial

    res = bench_spatial(1e-4)
    s, p = res["stage_3d"], res["stage_3d"]["planar"]
    assert s["max_rel_error"] == pytest.approx(p["max_rel_error"], rel=1e-2)
    assert s["max_rel_error"] < 1e-6 and s["reference_rel_error_estimate"] < 1e-8
    assert s["max_out_of_plane"] == 0.0
    assert res["tiptilt"]["max_rel_error"] < 1e-4
    assert s["linearizations"] == 1


def test_calls_of_any_size_and_a_replaced_state_step_as_one_call_from_that_state():
    """
    The stepping call seeds itself from the state it stepped last (y, command, F; to the bit).

    So steps split over calls must give one call's states, and a state the user sets, or a
    command changed in place, must be stepped from itself, never from the seed.
    """
    def fresh():
        sim = SpatialSimulation(load_spatial("tiptilt_stage"))
        sim.set_command([1e-6, 0.0, -1e-6])
        return sim

    whole, split = fresh(), fresh()
    whole.step(12)
    for n in (1, 0, 4, 7):
        split.step(n)
    assert whole.state.t == split.state.t
    assert whole.state.z.tobytes() == split.state.z.tobytes()
    assert whole.state.v.tobytes() == split.state.v.tobytes()
    # A state set by hand (displaced) and a command changed in place.
    start = whole.state.copy()
    start.z = start.z + 1e-7
    whole.state = start.copy()
    whole.state.command[1] = 5e-7
    whole.data.lin = None  # both runs take their Jacobian at `start` (it sets the last bits)
    whole.step(5)
    other = SpatialSimulation(load_spatial("tiptilt_stage"))
    other.state = start.copy()
    other.set_command([1e-6, 5e-7, -1e-6])
    other.step(5)
    assert whole.state.z.tobytes() == other.state.z.tobytes()
    assert whole.state.v.tobytes() == other.state.v.tobytes()
    # A command changed in place on the state just stepped (``set_command`` assigns it on
    # that state too).
    a, b = fresh(), fresh()
    a.step(3)
    b.step(3)
    a.state.command[1] = 5e-7
    b.state = b.state.copy()  # not the state b stepped last: nothing seeded
    b.set_command([1e-6, 5e-7, -1e-6])
    a.step(4)
    b.step(4)
    assert a.state.z.tobytes() == b.state.z.tobytes()
    split.step(5)  # the seeded run, displacement and command change missed
    assert np.max(np.abs(whole.state.z - split.state.z)) > 5e-8
