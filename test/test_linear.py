"""
Hyper-dual numbers, the generic force chain, and the exact linearisation.

modes, damped poles, frequency response against the time-domain engine, state space.
"""

import dataclasses

import numpy as np
import pytest

from flexure_sim.engine.kinematics import hyperdual as hd
from flexure_sim.engine.analysis import linear
from flexure_sim.engine.solver.assembly import Assembly
from flexure_sim.engine.mechanism.loader import load_mechanism, mechanism_from_dict
from flexure_sim.engine.laws.quadratic import QuadraticLaw
from flexure_sim.engine.mechanism.parameters import design_of, hinge_indices, twistor_flags
from flexure_sim.engine.analysis.parametric import forces
from flexure_sim.engine.solver.simulation import Simulation, State
from reference_figures import FIRST_MODE_HZ

U0 = 1.35e-6
EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def stage():
    return load_mechanism("microstage")


@pytest.fixture(scope="module")
def stage_model(stage):
    return linear.linearize(Simulation(stage), U0)


# ------------------------------------------------------------------- hyper-dual


def test_hyperdual_parts_equal_hand_derivatives_to_machine_precision():
    # f(x, y) = sin(x) e^y / y: f_x = cos x e^y / y, f_y = sin x e^y (y - 1) / y^2,
    # f_xy = cos x e^y (y - 1) / y^2.
    x0, y0 = 0.7, 1.3
    f = np.sin(hd.seed(x0, 1.0, 0.0)) * np.exp(hd.seed(y0, 0.0, 1.0)) / hd.seed(y0, 0.0, 1.0)
    e = np.exp(y0)
    assert f.a == pytest.approx(np.sin(x0) * e / y0, rel=4 * EPS)
    assert f.b == pytest.approx(np.cos(x0) * e / y0, rel=4 * EPS)
    assert f.c == pytest.approx(np.sin(x0) * e * (y0 - 1) / y0**2, rel=8 * EPS)
    assert f.d == pytest.approx(np.cos(x0) * e * (y0 - 1) / y0**2, rel=8 * EPS)


def test_hyperdual_composites_with_known_derivatives():
    x = hd.seed(np.array([0.3, 1.7, 2.9]), 1.0, 1.0)
    y = hd.seed(np.array([0.4, -0.8, 1.1]), 0.0, 0.0)
    # sqrt(x^2 + y^2) cos(atan2(y, x)) = x in every quadrant: derivatives 1 and 0.
    for sx in (1.0, -1.0):
        xs = hd.seed(sx * x.a, 1.0, 1.0)
        g = np.sqrt(xs * xs + y * y) * np.cos(np.arctan2(y, xs))
        np.testing.assert_allclose(g.a, xs.a, rtol=4 * EPS)
        np.testing.assert_allclose(g.b, 1.0, rtol=0, atol=8 * EPS)
        np.testing.assert_allclose(g.d, 0.0, rtol=0, atol=32 * EPS)
    # exp(log x * 3) = x^3: second derivative 6x; tan(arctan(x)) = x.
    h = np.exp(np.log(x) * 3.0)
    np.testing.assert_allclose(h.d, 6 * x.a, rtol=16 * EPS)
    t = np.tan(np.arctan(x)) + x**2.5 - x**2.5
    np.testing.assert_allclose(t.b, 1.0, rtol=16 * EPS)
    np.testing.assert_allclose((1.0 / x).d, 2.0 / x.a**3, rtol=4 * EPS)


def test_a_complex_step_on_the_hyperdual_parts_gives_the_third_derivative():
    """
    Im(f(x + ih)) / h of the e1e2 part is the third derivative, to machine precision.

    The construction engine/analysis/sensitivity.py uses for the first mode's second derivative.
    f = sin(x) sqrt(x): f''' = -cos x sqrt x - (3/2) sin x / sqrt x - (3/4) cos x / x^1.5
    + (3/8) sin x / x^2.5.
    """
    x0, h = 0.9, 1e-30
    x = hd.HyperDual(x0 + 1j * h, 1.0, 1.0, 0.0)
    f = np.sin(x) * np.sqrt(x)
    s, c, r = np.sin(x0), np.cos(x0), np.sqrt(x0)
    third = -c * r - 1.5 * s / r - 0.75 * c / x0**1.5 + 0.375 * s / x0**2.5
    assert np.imag(f.d) / h == pytest.approx(third, rel=16 * EPS)
    assert np.real(f.d) == pytest.approx(-s * r + c / r - 0.25 * s / x0**1.5, rel=16 * EPS)


def test_hyperdual_flows_through_the_notch_stiffness_formula():
    from flexure_sim.engine.hinges.stiffness import notch_stiffness

    h0 = 0.25e-3
    K = hd.from_objects(notch_stiffness(3e-3, hd.seed(h0, 1.0, 1.0), 0.02, 69e9, 0.33))
    # Ko = kappa E t h^2 with kappa = -0.035 h/D + 0.1109 sqrt(h/D): differentiate by hand.
    D, E, t = 3e-3, 69e9, 0.02
    dKo = E * t * (-0.035 * 3 * h0**2 / D + 0.1109 * 2.5 * h0**1.5 / np.sqrt(D))
    d2Ko = E * t * (-0.035 * 6 * h0 / D + 0.1109 * 3.75 * h0**0.5 / np.sqrt(D))
    assert K.b[0, 0] == pytest.approx(dKo, rel=1e-14)
    assert K.d[0, 0] == pytest.approx(d2Ko, rel=1e-14)


# ---------------------------------------------------------------- force chain


@pytest.mark.parametrize("name", ["microstage", "fourbar_mixed"])
def test_generic_force_chain_matches_the_engine_and_its_jacobians(name):
    mech = load_mechanism(name)
    asm = Assembly(mech)
    rng = np.random.default_rng(3)
    z0 = np.array([b.pose for b in mech.bodies], dtype=float).ravel()
    z = z0 + rng.normal(size=z0.size) * np.tile([1e-5, 1e-5, 3e-2], len(mech.bodies))
    v = rng.normal(size=z0.size) * 1e-3
    ref = asm.forces(z, v, jacobian=True)
    ia, ib = hinge_indices(mech)
    N = z.size
    f = forces(
        design_of(mech),
        twistor_flags(mech),
        ia,
        ib,
        hd.HyperDual(z, np.eye(N), 0, 0),
        hd.HyperDual(v, 0, np.eye(N), 0),
    )
    scale = np.max(np.abs(ref.Q))
    np.testing.assert_allclose(f.Q.a, ref.Q, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(
        f.wrench.a, ref.wrench_b, rtol=0, atol=1e-13 * np.max(np.abs(ref.wrench_b))
    )
    np.testing.assert_allclose(f.Q.b.T, ref.dQ_dz, rtol=0, atol=1e-13 * np.max(np.abs(ref.dQ_dz)))
    np.testing.assert_allclose(f.Q.c.T, ref.dQ_dv, rtol=0, atol=1e-13 * np.max(np.abs(ref.dQ_dv)))


# ----------------------------------------------------------------------- modes


def _single_body(Ko=2.0, kx=3e6, ky=5e5, m=0.02, inertia=4e-6):
    return mechanism_from_dict(
        {
            "name": "single",
            "defaults": {"law": "twistor", "damping": {"t_char": 1e-4}},
            "bodies": [
                {"name": "ground", "mass": 1.0, "inertia": 1.0, "pose": [0, 0, 0]},
                {"name": "mass", "mass": m, "inertia": inertia, "pose": [0.01, 0.0, 0.0]},
            ],
            "hinges": [
                {
                    "name": "h",
                    "a": {"body": "ground", "at": [0.01, 0.0]},
                    "b": {"body": "mass", "at": [0, 0]},
                    "stiffness": {"model": "matrix", "Ko": Ko, "Kt": [kx, ky]},
                }
            ],
            "constraints": [{"type": "fixed", "body": "ground"}],
        }
    )


def test_one_body_one_hinge_frequencies_are_sqrt_k_over_m():
    Ko, kx, ky, m, inertia = 2.0, 3e6, 5e5, 0.02, 4e-6
    md = linear.modes(linear.linearize(Simulation(_single_body(Ko, kx, ky, m, inertia)), 0.0))
    expected = np.sort([np.sqrt(kx / m), np.sqrt(ky / m), np.sqrt(Ko / inertia)]) / (2 * np.pi)
    np.testing.assert_allclose(md.frequencies, expected, rtol=1e-12)


def test_mode_shapes_are_mass_orthonormal_and_diagonalise_the_stiffness(stage_model):
    md = linear.modes(stage_model)
    Phi, M = md.shapes, np.diag(stage_model.mass)
    np.testing.assert_allclose(Phi.T @ M @ Phi, np.eye(len(Phi)), atol=1e-10)
    w2 = (2 * np.pi * md.frequencies) ** 2
    np.testing.assert_allclose(
        Phi.T @ stage_model.stiffness @ Phi, np.diag(w2), atol=1e-9 * w2.max()
    )


def _scaled_damping(mech, s):
    hinges = tuple(
        dataclasses.replace(h, law=QuadraticLaw(h.law.coordinates, h.law.K, h.law.B * s))
        for h in mech.hinges
    )
    return dataclasses.replace(mech, hinges=hinges)


def test_damped_poles_tend_to_the_undamped_frequencies_as_damping_vanishes(stage):
    undamped = linear.modes(linear.linearize(Simulation(stage), U0)).frequencies
    errors = []
    for s in (1e-3, 1e-5, 1e-7):
        poles = linear.modes(linear.linearize(Simulation(_scaled_damping(stage, s)), U0)).poles
        upper = np.sort(poles[poles.imag > 0].imag) / (2 * np.pi)
        assert len(upper) == len(undamped)
        errors.append(np.max(np.abs(upper - undamped) / undamped))
    # Im(pole) = omega sqrt(1 - zeta^2) with zeta proportional to the damping scale.
    assert errors[2] < 1e-9
    assert errors[0] > errors[1] > errors[2]


def test_stage_first_mode_is_overdamped_pair_with_the_actuator_pole(stage_model):
    md = linear.modes(stage_model)
    assert 250 < md.frequencies[0] < 350
    assert np.any(np.isclose(md.poles, -1000.0, rtol=1e-12))  # actuator lag 1 ms


# ------------------------------------------------------------ frequency response


def test_frf_at_the_lowest_frequency_is_the_static_gain(stage, stage_model):
    sim = Simulation(stage)
    h = 1e-10
    hi, lo = sim.static(U0 + h).snapshot, sim.static(U0 - h).snapshot
    fd = {
        "output": (hi.output - lo.output) / (2 * h),
        "compression": (hi.compression - lo.compression) / (2 * h),
        "drive_force": (hi.drive_force - lo.drive_force) / (2 * h),
        "hinges.c.moment": (hi.wrenches[2, 0] - lo.wrenches[2, 0]) / (2 * h),
    }
    G = linear.frf(stage_model, [1e-6], list(fd))[:, 0]
    for (name, want), got in zip(fd.items(), G):
        assert abs(got - want) / abs(want) < 1e-6, name


def _sine_response(sim, z_static, u0, amp, freq, dt, body, axis):
    """
    Drive command u0 + amp sin(2 pi f t).

    Sampled at each step's midpoint (so the piecewise-constant command has no half-step delay);
    output samples after each step.
    """
    sim.state = State(0.0, z_static.copy(), np.zeros_like(z_static), u0, u0)
    periods = max(2, int(np.ceil(0.005 * freq)))
    n_transient = int(round(0.03 / dt))
    n_fit = int(round(periods / freq / dt))
    t = np.empty(n_fit)
    y = np.empty(n_fit)
    i = 3 * body
    for k in range(n_transient + n_fit):
        sim.set_command(u0 + amp * np.sin(2 * np.pi * freq * (k + 0.5) * dt))
        sim.step()
        if k >= n_transient:
            t[k - n_transient] = sim.state.t
            y[k - n_transient] = (sim.state.z[i:i + 2] - sim.z0[i:i + 2]) @ axis
    basis = np.column_stack(
        [np.sin(2 * np.pi * freq * t), np.cos(2 * np.pi * freq * t), np.ones_like(t)]
    )
    (a, b, _), *_ = np.linalg.lstsq(basis, y, rcond=None)
    return (a + 1j * b) / amp  # y = Im(G e^{i w t}) amp = amp (Re G sin + Im G cos)


@pytest.mark.slow
def test_frf_matches_time_domain_sine_response(stage, stage_model):
    md = linear.modes(stage_model)
    sim = Simulation(stage, dt=2e-6)
    body = stage.body_index(stage.output.body)
    axis = np.array(stage.output.axis)
    for freq in (40.0, md.frequencies[0], 900.0):
        measured = _sine_response(sim, stage_model.z, U0, 1e-9, freq, sim.dt, body, axis)
        G = linear.frf(stage_model, [freq], ["output"])[0, 0]
        assert abs(abs(measured) - abs(G)) / abs(G) < 1e-3, freq
        assert abs(np.angle(measured / G)) < 1e-3, freq


def test_jacobian_of_the_model_is_the_engines(stage, stage_model):
    sim = Simulation(stage)
    nF = len(stage_model.free)
    y = np.concatenate([stage_model.z[stage_model.free], np.zeros(nF), [U0]])
    np.testing.assert_array_equal(stage_model.A, sim.model.jacobian(y, 0.0, np.array([U0])))


# ------------------------------------------------------------- CLI, state space


def _cli(*argv):
    from flexure_sim.cli import main

    return main([str(a) for a in argv])


def test_linearize_exports_a_model_python_control_loads_and_its_bode_matches_frf(tmp_path, capsys):
    import json

    import control
    import scipy.io

    assert _cli("linearize", "microstage", "--input", U0, "-o", tmp_path / "m.npz") == 0
    assert _cli("linearize", "microstage", "--input", U0, "-o", tmp_path / "m.mat") == 0
    assert (
        _cli(
            "frf",
            "microstage",
            "--input",
            U0,
            "--to",
            "output",
            "--to",
            "hinges.c.moment",
            "--fmin",
            10,
            "--fmax",
            1e4,
            "--points",
            50,
            "--csv",
            "-o",
            tmp_path,
        )
        == 0
    )
    data = np.load(tmp_path / "m.npz")
    sys = control.ss(data["A"], data["B"], data["C"], data["D"])
    header = (tmp_path / "frf.csv").read_text().splitlines()[0].split(",")
    table = np.loadtxt(tmp_path / "frf.csv", delimiter=",", skiprows=1)
    csv = {name: table[:, k] for k, name in enumerate(header)}
    names = list(data["output_names"])
    for out in ("output", "hinges.c.moment"):
        sub = control.ss(
            data["A"], data["B"], data["C"][[names.index(out)]], data["D"][[names.index(out)]]
        )
        resp = control.frequency_response(sub, 2 * np.pi * csv["frequency_hz"])
        G = np.squeeze(resp.complex)
        want = csv[f"{out}.real"] + 1j * csv[f"{out}.imag"]
        np.testing.assert_allclose(G, want, rtol=1e-8)
    assert sys.nstates == 25
    mat = scipy.io.loadmat(tmp_path / "m.mat")
    np.testing.assert_array_equal(mat["A"], data["A"])
    assert str(np.ravel(mat["output_names"])[0][0]) == "output"  # a MATLAB cell array of strings
    assert _cli("linearize", "microstage", "--input", U0, "-o", tmp_path / "m.json") == 0
    model = json.loads((tmp_path / "m.json").read_text())
    np.testing.assert_array_equal(np.array(model["C"]), data["C"])
    assert model["state_names"][0] == "body2.x" and model["input_names"] == ["drive"]
    _check_bode_png(tmp_path / "frf.png", csv, ("output", "hinges.c.moment"))
    assert _cli("linearize", "microstage", "-o", tmp_path / "m.txt") == 2
    assert "must end in .npz, .mat or .json" in capsys.readouterr().err


# The plots are read back as pixels (matplotlib.image.imread): matplotlib's default colours C0
# (blue) and C1 (orange), the mode plots' grey rest drawing (0.7) and red hinge markers (C3).
BLUE, ORANGE, GREY, RED = (31, 119, 180), (255, 127, 14), (179, 179, 179), (214, 39, 40)


def _png(path):
    """Return the RGB pixels of a PNG file (checked to be one by its signature)."""
    import matplotlib.image

    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", path
    return matplotlib.image.imread(path)[..., :3]


def _colour(img, rgb, tol=0.05):
    return np.linalg.norm(img - np.array(rgb) / 255.0, axis=-1) < tol


def _in_long_runs(mask, n=10):
    """Pixels of mask in a horizontal or vertical run of at least n: lines, not text strokes."""
    out = np.zeros_like(mask)
    for axis in (0, 1):
        full = np.lib.stride_tricks.sliding_window_view(mask, n, axis=axis).all(-1)
        for k in range(n):
            sl = [slice(None), slice(None)]
            sl[axis] = slice(k, k + full.shape[axis])
            out[tuple(sl)] |= full
    return out


def _rest_lines_visible(img):
    """
    Grey pixels in straight runs inside the drawing's box (blue and red pixels' extent).

    The displaced drawing (blue, 2 pt) is drawn over the rest drawing (grey, 1.5 pt): grey
    lines show only where the mode moves a body.
    """
    rows, cols = np.nonzero(_colour(img, BLUE) | _colour(img, RED))
    box = (slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1))
    return int(_in_long_runs(_colour(img, GREY))[box].sum())


def test_modes_command_json_and_plots(tmp_path, capsys):
    import json

    assert _cli("modes", "microstage", "--count", 2, "--json", "-o", tmp_path) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["undamped_frequencies_hz"][0] == pytest.approx(FIRST_MODE_HZ, rel=1e-3)
    assert out["plots"] == [str(tmp_path / f"mode_{k}.png") for k in (1, 2)]
    images = [_png(tmp_path / f"mode_{k}.png") for k in (1, 2)]
    for img in images:
        assert img.shape == (550, 660, 3)  # figsize 6 x 5 in at 110 dpi
        assert _colour(img, BLUE).sum() > 2000  # the displaced bodies (~4000 px)
        assert _colour(img, RED).sum() > 200  # 14 hinge markers (~400 px)
        # The rest drawing shows beside the displaced one (mode 1: ~1000 px, mode 2: ~600).
        assert _rest_lines_visible(img) > 300
    # The two modes are different drawings.
    assert np.mean(np.abs(images[0] - images[1]).max(axis=-1) > 0.1) > 0.02
    assert _cli("modes", "no_such_stage") == 2
    assert "no such built-in mechanism" in capsys.readouterr().err


def test_a_mode_plot_without_motion_hides_the_rest_drawing(tmp_path):
    """
    The control for the grey-pixel count above: a zero mode shape draws blue over all grey.

    So the count measures the drawn displacement, not the plot's furniture.
    """
    from flexure_sim.tools.design.linear_plots import plot_modes

    mech = load_mechanism("microstage")
    model = linear.linearize(Simulation(mech), 0.0, wrenches=False)
    md = linear.modes(model)
    still = dataclasses.replace(md, shapes=np.zeros_like(md.shapes))
    (path,) = plot_modes(mech, model, still, 1, tmp_path)
    img = _png(path)
    assert _colour(img, BLUE).sum() > 2000
    assert _rest_lines_visible(img) < 30


def test_mode_plot_points_are_the_files_hinge_points_moved_by_the_mode_shape():
    """
    The plotted points: at rest the YAML's hinge points; the first mode moves the output along x.

    Rest: every body's pose in config/microstage.yaml plus its hinge frames' `at` (all poses
    have angle 0). Displaced: ground fixed; the output body (body4) translates along the drive
    axis x (the first mode swings the levers together), its points alike (a translation).
    """
    import yaml

    from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
    from flexure_sim.tools.design.linear_plots import _mode_points

    data = yaml.safe_load(resolve_mechanism_path("microstage").read_text())
    pose = {b["name"]: np.array(b["pose"][:2]) for b in data["bodies"]}
    expected = {name: [p] for name, p in pose.items()}
    for h in data["hinges"]:
        for side in ("a", "b"):
            f = h[side]
            expected[f["body"]].append(pose[f["body"]] + np.array(f["at"]))
    mech = load_mechanism("microstage")
    model = linear.linearize(Simulation(mech), 0.0, wrenches=False)
    md = linear.modes(model)
    points = {b.name: [] for b in mech.bodies}
    for h in mech.hinges:
        points[h.a.body].append(h.a.position)
        points[h.b.body].append(h.b.position)
    dz = np.zeros_like(model.z)
    dz[model.free] = md.shapes[:, 0]
    pts = _mode_points(mech, points, model.z, dz)
    for name, (rest, disp) in pts.items():
        np.testing.assert_allclose(rest, np.array(expected[name]), rtol=0, atol=1e-15)
    rest, disp = pts["body1"]
    np.testing.assert_array_equal(disp, rest)
    move = pts["body4"][1] - pts["body4"][0]
    assert np.all(np.abs(move[:, 0]) > 1.0)  # M-normalised shape: ~6 m / sqrt(kg)
    assert np.max(np.abs(move[:, 1])) < 1e-2 * np.min(np.abs(move[:, 0]))
    # A translation: the points 28 mm apart move alike to 1e-3 (rotation ~0.36 rad per unit).
    np.testing.assert_allclose(
        move, np.broadcast_to(move[0], move.shape), rtol=0, atol=2e-3 * abs(move[0, 0])
    )


def _check_bode_png(path, csv, outputs):
    """
    Check that the Bode PNG draws the CSV's curves where the CSV says they are.

    Read back from the pixels (matplotlib's C0, C1 for the two outputs): the phase panel (no
    legend) gives the log-frequency axis from the curves' ends (fmin, fmax) and a linear
    phase axis fitted to two curve ends, which must then place the other two ends and every
    curve's phase at 1 kHz; the magnitude panel, log-scaled, is fitted to the two curves at
    1 kHz and must place them at fmax.
    """
    img = _png(path)
    assert img.shape == (660, 770, 3)  # figsize 7 x 6 in at 110 dpi
    half = img.shape[0] // 2  # the panels' gap (no curve pixels there)
    masks = [_colour(img, BLUE, 0.1), _colour(img, ORANGE, 0.1)]
    assert not any(m[half - 5:half + 5].any() for m in masks)
    top = [m[:half] for m in masks]
    bottom = [m[half:] for m in masks]
    f = csv["frequency_hz"]
    cols = np.nonzero(bottom[0].any(axis=0))[0]
    c_lo, c_hi = cols.min(), cols.max()
    for m in bottom[1:]:
        c = np.nonzero(m.any(axis=0))[0]
        assert abs(c.min() - c_lo) <= 1 and abs(c.max() - c_hi) <= 1

    def column(freq):
        t = (np.log10(freq) - np.log10(f[0])) / (np.log10(f[-1]) - np.log10(f[0]))
        return int(round(c_lo + t * (c_hi - c_lo)))

    def row(mask, c):
        r = np.nonzero(mask[:, c - 1:c + 2].any(axis=1))[0]
        assert len(r) and np.ptp(r) < 12, (c, r)  # one thin curve at this column
        return r.mean()

    def interp(values, freq):
        return np.interp(np.log10(freq), np.log10(f), values)

    phase = [csv[f"{o}.phase_deg"] for o in outputs]
    # Phase: fit row = a + b phase on curve 0 at both ends, check curve 1's ends and 1 kHz.
    (c0_lo, c0_hi) = (row(bottom[0], c_lo + 1), row(bottom[0], c_hi - 1))
    b = (c0_hi - c0_lo) / (phase[0][-1] - phase[0][0])
    a = c0_lo - b * phase[0][0]
    assert b < 0  # phase up, rows down
    span = abs(b) * (phase[0][0] - phase[0][-1])
    for k, m in enumerate(bottom):
        for c, want in ((c_lo + 1, phase[k][0]), (c_hi - 1, phase[k][-1]),
                        (column(1e3), interp(phase[k], 1e3))):
            assert abs(row(m, c) - (a + b * want)) < 0.02 * span, (outputs[k], c)
    # Magnitude: log scale fitted to both curves at 1 kHz, checked at fmax.
    mag = [np.log10(csv[f"{o}.magnitude"]) for o in outputs]
    r_k = [row(top[k], column(1e3)) for k in range(2)]
    b = (r_k[1] - r_k[0]) / (interp(mag[1], 1e3) - interp(mag[0], 1e3))
    a = r_k[0] - b * interp(mag[0], 1e3)
    assert b < 0
    for k in range(2):
        assert abs(row(top[k], c_hi - 1) - (a + b * mag[k][-1])) < 4, outputs[k]


def test_modal_damping_of_proportional_damping_is_omega_t_char_over_two(stage):
    # At rest B = t_char K (t_char = 1 ms) makes the damping tangent t_char times the
    # stiffness tangent: phi^T C phi = t_char omega^2, so zeta = omega t_char / 2; the first
    # mode (0.94) is the only one below critical damping, and its pole pair is
    # omega (-zeta +- i sqrt(1 - zeta^2)). (Under load the geometric stiffness terms make
    # the damping slightly non-proportional: 5e-6 at 1.35 um.)
    md = linear.modes(linear.linearize(Simulation(stage), 0.0, wrenches=False))
    omega = 2 * np.pi * md.frequencies
    np.testing.assert_allclose(md.modal_damping, omega * 1e-3 / 2, rtol=1e-9)
    z1 = md.modal_damping[0]
    pair = md.poles[md.poles.imag > 0]
    assert len(pair) == 1
    assert pair[0] == pytest.approx(omega[0] * (-z1 + 1j * np.sqrt(1 - z1**2)), rel=1e-9)
