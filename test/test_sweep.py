"""
flexure-sim sweep.

Outputs against independent figures, failed designs, Ctrl-C and --resume, a LocalCluster worker
killed mid-study, bit-identical results for any worker count.
"""
import fcntl
import json
import math
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from flexure_sim.engine.mechanism.loader import load_mechanism
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.analysis.study import load_study, study_from_dict
from flexure_sim.tools.run import response_metrics
from flexure_sim.tools.design import sweep_run as sweep, sweep_summary
from flexure_sim.tools.design.sweep_outputs import OUTPUTS, evaluate_batch
from reference_figures import JOINT_A_COMPRESSION, STAGE_GAIN

ROOT = Path(__file__).resolve().parent.parent
STAGE_STUDY = ROOT / "config" / "studies" / "stage_tolerance.yaml"


def _small_stage_study(tmp_path: Path, samples=200, batch_size=20, **over) -> Path:
    """Return the shipped stage tolerance study, with fewer designs."""
    data = yaml.safe_load(STAGE_STUDY.read_text())
    data.update(samples=samples, batch_size=batch_size, **over)
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _cli(*args, cwd: Path, env=None, **kw) -> subprocess.CompletedProcess:
    env = {**(env or os.environ), "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    return subprocess.run([sys.executable, "-m", "flexure_sim.cli", "sweep", *map(str, args)],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=300, **kw)


def _grid(values, outputs=("gain", "compression", "drive_force"), input=1.35e-6, **over):
    data = {"mechanism": "microstage", "input": input, "outputs": list(outputs),
            "parameters": [{"name": "h", "path": "stiffness_models.notch.h", "values": values}],
            **over}
    return study_from_dict(data, "grid.yaml", OUTPUTS)


class _OneLineAhead:
    """
    A child's stderr that holds one write at a time: the child runs at most a line ahead.

    A packet-mode pipe (O_DIRECT) of one page takes one write; the child's next write blocks
    until the test reads. A study that prints a line per batch cannot finish before the test's
    Ctrl-C, however busy the machine (the test waits for an event, never for a time).
    """

    def __init__(self):
        self.read_end, self.write_end = os.pipe2(os.O_DIRECT | os.O_CLOEXEC)
        fcntl.fcntl(self.write_end, fcntl.F_SETPIPE_SZ, 4096)
        self.rest: list[bytes] = []
        self._drain = threading.Thread(target=self._read_to_end, daemon=True)

    def started(self) -> None:
        """Close our write end once the child holds it, so the end of its output is seen."""
        os.close(self.write_end)

    def line(self) -> str:
        """
        Wait for the child's next progress line and return it.

        Other writes before it are kept in `rest`: Dask warns there when another cluster holds
        its default HTTP port (two studies at once, as the suite's two workers can run).
        """
        while True:
            text = os.read(self.read_end, 65536).decode()
            if not text or text.startswith("flexure-sim sweep:"):
                return text
            self.rest.append(text.encode())

    def _read_to_end(self) -> None:
        while chunk := os.read(self.read_end, 65536):
            self.rest.append(chunk)

    def finish(self, proc: subprocess.Popen, timeout: float) -> str:
        """Read the child's remaining output while it ends; return that output."""
        self._drain.start()
        proc.wait(timeout=timeout)
        self._drain.join(timeout=timeout)  # the LocalCluster's workers hold the pipe too
        assert not self._drain.is_alive(), "the child's processes kept stderr open"
        os.close(self.read_end)
        return b"".join(self.rest).decode()


# ------------------------------------------------------------------------------ outputs
def test_nominal_stage_outputs_match_the_reference_figures():
    """
    Gain 27.628 and compression 192.2 nm at 1.35 um; drive force = dU/du.

    README: an independent reimplementation agrees on gain and compression. The drive force
    is checked by central differences of the potential energy of two static solves (a second
    method).
    """
    cols = evaluate_batch(_grid([2.5e-4]), 0, 1)
    assert cols["status"] == ["ok"]
    assert cols["gain"][0] == pytest.approx(STAGE_GAIN, rel=1e-4)
    assert cols["compression"][0] == pytest.approx(JOINT_A_COMPRESSION, rel=1e-3)
    sim, du = Simulation(load_mechanism("microstage")), 1e-9
    U = [sim.static(1.35e-6 + s * du).snapshot.potential_energy for s in (1, -1)]
    dU = U[0] - U[1]
    assert cols["drive_force"][0] == pytest.approx(dU / (2 * du), rel=1e-5)


def test_step_outputs_agree_with_an_independent_integrator():
    """
    Settling time and overshoot of the step to 1.35 um equal those of scipy's Radau.

    The same equations integrated by scipy's Radau (rtol 1e-9, exact Jacobian), sampled at the
    same instants.
    """
    from scipy.integrate import solve_ivp

    study = _grid([2.5e-4], outputs=("settling_time", "overshoot"),
                  step={"duration": 0.02, "dt": 1e-4})
    cols = evaluate_batch(study, 0, 1)
    sim = Simulation(load_mechanism("microstage"), dt=1e-4)
    sim.set_command(1.35e-6)
    t = 1e-4 * np.arange(1, 201)
    angle = sim.part.free % 3 == 2  # atol: 1e-10 of each component's scale of motion
    scale = np.concatenate([np.where(angle, 1e-3, 1e-5), np.where(angle, 1.0, 1e-2), [1.35e-6]])
    model = sim.model
    command = np.array([1.35e-6])
    sol = solve_ivp(lambda tt, y: model.rhs(y, tt, command)[0], (0, 0.02), model.pack(sim.state),
                    method="Radau", jac=lambda tt, y: model.jacobian(y, tt, command), rtol=1e-9,
                    atol=1e-10 * scale, t_eval=t)
    i = sim.mechanism.body_index("body4")
    col = list(sim.part.free).index(3 * i)
    ref = response_metrics.step_response(t, sol.y[col] - sim.z0[3 * i], 0.0, 0.0)
    assert ref.settling_time is not None and ref.overshoot > 0
    assert cols["settling_time"][0] == pytest.approx(ref.settling_time, rel=1e-4)
    assert cols["overshoot"][0] == pytest.approx(ref.overshoot, rel=1e-3, abs=1e-7)


def test_outputs_do_not_depend_on_their_order():
    """The static and the dynamic outputs share one simulation per design."""
    names = ["gain", "settling_time", "drive_force", "overshoot"]
    a = evaluate_batch(_grid([2.4e-4, 2.5e-4], outputs=names), 0, 2)
    b = evaluate_batch(_grid([2.4e-4, 2.5e-4], outputs=names[::-1]), 0, 2)
    for name in names:
        assert a[name].tobytes() == b[name].tobytes()


@pytest.mark.slow
def test_monte_carlo_spread_of_the_gain_agrees_with_the_first_order_prediction(tmp_path):
    """
    2000 designs of the stage study (h +- 5 um on all seven hinges, independent).

    To first order the standard deviation of the gain is sqrt(sum (dg/dh_i)^2) * 5 um, with dg/dh_i
    the exact sensitivities (engine/analysis/sensitivity.py, hyper-dual). The sample standard
    deviation of n normal values has a relative standard error 1/sqrt(2 (n - 1)): agreement within
    4 of those, plus 1 % for the neglected second-order terms (the second derivatives times (5
    um)^2 are below 1e-3 of the first-order spread).
    """
    from flexure_sim.engine.mechanism.parameters import Parameters
    from flexure_sim.engine.analysis.sensitivity import sensitivities

    study = load_study(_small_stage_study(tmp_path, samples=2000, batch_size=2000,
                                          outputs=["gain"]), OUTPUTS)
    gain = evaluate_batch(study, 0, 2000)["gain"]
    paths = [p["path"] for p in yaml.safe_load(STAGE_STUDY.read_text())["parameters"]]
    assert paths == [f"hinges.{h}.stiffness.h" for h in "abcdefg"]
    assert all(p.kind == "normal" and p.scale == 5e-6 for p in study.parameters)
    sens = sensitivities(Parameters(study.mechanism_source, data=study.base), paths, ["gain"],
                         study.input)
    slopes = [sens["gradient"]["gain"][p] for p in paths]
    predicted = math.sqrt(sum(s * s for s in slopes)) * 5e-6
    assert abs(gain.std(ddof=1) / predicted - 1) < 4 / math.sqrt(2 * 1999) + 0.01


def _rider_doc(mass=0.02, k=(2.0, 3e6, 5e5), inertia=4e-6, t_char=1e-5, sigma_y="276.0e6"):
    """
    Return a driven body held to ground by a leaf along the drive axis (y).

    With it, a free body riding on the driven one through a matrix hinge at its mass centre.
    """
    leaf = {"model": "cantilever", "length": 0.01, "thickness": 0.001, "width": 0.005,
            "E": "69.0e9", "nu": 0.33}
    if sigma_y is not None:
        leaf["sigma_y"] = sigma_y
    return {
        "name": "rider",
        "defaults": {"law": "twistor", "damping": {"t_char": t_char}},
        "bodies": [{"name": "ground", "mass": 1.0, "inertia": 1.0, "pose": [0, 0, 0]},
                   {"name": "driver", "mass": 0.1, "inertia": 1e-5, "pose": [0, 0.02, 0]},
                   {"name": "rider", "mass": mass, "inertia": inertia, "pose": [0.03, 0.02, 0]}],
        "hinges": [
            {"name": "leaf", "a": {"body": "ground", "at": [0, 0.01]},
             "b": {"body": "driver", "at": [0, -0.01]}, "stiffness": leaf},
            {"name": "ride", "a": {"body": "driver", "at": [0.03, 0]},
             "b": {"body": "rider", "at": [0, 0]},
             "stiffness": {"model": "matrix", "Ko": k[0], "Kt": [k[1], k[2]]}},
        ],
        "constraints": [{"type": "fixed", "body": "ground"},
                        {"type": "drive", "body": "driver", "axis": [0, 1],
                         "response_time": 1e-3, "stroke": [0, 2e-6], "slew_rate": 0.01}],
    }


def _rider_study(tmp_path, outputs, masses=(0.02, 0.05), **doc):
    (tmp_path / "rider.yaml").write_text(yaml.safe_dump(_rider_doc(**doc)))
    data = {"mechanism": "rider.yaml", "input": 2e-6, "outputs": list(outputs),
            "parameters": [{"name": "m", "path": "bodies.rider.mass", "values": list(masses)}]}
    return study_from_dict(data, str(tmp_path / "s.yaml"), OUTPUTS, base_dir=tmp_path)


def test_first_mode_and_its_damping_ratio_of_a_mass_on_a_spring_are_the_closed_forms(tmp_path):
    """
    The rider.

    First mode sqrt(k_min / m) / 2 pi of its three springs (k = 2 N m/rad on I = 4e-6 kg m^2 for
    the light rider: 112.5 Hz; 5e5 N/m along y on the 2 kg one: 79.6 Hz); damping ratio c / (2
    sqrt(k m)) with c = t_char k.
    """
    t_char = 1e-5
    cols = evaluate_batch(_rider_study(tmp_path, ["first_mode", "first_mode_damping"],
                                       masses=(0.02, 2.0), t_char=t_char), 0, 2)
    assert cols["status"] == ["ok", "ok"]
    for r, m in enumerate((0.02, 2.0)):
        k, mass = min([(2.0, 4e-6), (5e5, m)], key=lambda km: km[0] / km[1])
        omega = math.sqrt(k / mass)
        assert cols["first_mode"][r] == pytest.approx(omega / (2 * math.pi), rel=1e-9)
        c = t_char * k
        zeta = c / (2 * math.sqrt(k * mass))
        assert cols["first_mode_damping"][r] == pytest.approx(zeta, rel=1e-9)


def test_first_mode_is_the_ringing_period_of_a_free_vibration_time_simulation(tmp_path):
    """
    The 2 kg rider rings at its first mode after a step of the drive (base excitation).

    Once the actuator's 1 ms lag has died out the motion is a free damped vibration, whose zero
    crossings (time-domain engine, dt = 10 us) are half a period 1 / (f sqrt(1 - zeta^2)) apart,
    with f and zeta the sweep's first_mode and first_mode_damping.
    """
    study = _rider_study(tmp_path, ["first_mode", "first_mode_damping"], masses=(2.0,))
    cols = evaluate_batch(study, 0, 1)
    f, zeta = cols["first_mode"][0], cols["first_mode_damping"][0]
    sim = Simulation(study.mechanism([2.0]), dt=1e-5)
    i = sim.mechanism.body_index("rider")
    sim.set_command(2e-6)
    t, y = [], []
    for _ in range(10000):  # 0.1 s
        sim.step()
        t.append(sim.state.t)
        y.append(sim.state.z[3 * i + 1] - sim.z0[3 * i + 1] - 2e-6)
    t, y = np.array(t), np.array(y)
    late = t > 0.03  # actuator transient exp(-30) gone
    t, y = t[late], y[late]
    k = np.nonzero(np.sign(y[1:]) != np.sign(y[:-1]))[0]
    crossings = t[k] - y[k] * (t[k + 1] - t[k]) / (y[k + 1] - y[k])
    assert len(crossings) >= 8
    period = 2 * np.mean(np.diff(crossings))
    assert period == pytest.approx(1 / (f * math.sqrt(1 - zeta**2)), rel=1e-6)


def test_peak_stress_ratio_of_a_leaf_stretched_along_its_axis_is_e_strain_over_yield(tmp_path):
    """
    The drive stretches the leaf by u along its axis.

    Sigma = E u / L (Hooke), no bending, over sigma_y. 69 GPa * 2 um / 10 mm = 13.8 MPa; / 276 MPa
    = 0.05.
    """
    cols = evaluate_batch(_rider_study(tmp_path, ["peak_stress_ratio"]), 0, 2)
    assert cols["status"] == ["ok", "ok"]
    np.testing.assert_allclose(cols["peak_stress_ratio"], 69e9 * 2e-6 / 0.01 / 276e6,
                               rtol=1e-9)
    # Without any sigma_y the study is refused at load, naming the output.
    with pytest.raises(Exception, match="outputs: peak_stress_ratio: no hinge of 'rider'"):
        _rider_study(tmp_path, ["gain", "peak_stress_ratio"], sigma_y=None)


def test_stage_first_mode_outputs_are_what_the_modes_command_reports(tmp_path):
    """
    Check first_mode and first_mode_damping of the nominal stage at 2 um.

    They equal `flexure-sim modes microstage --input 2e-6 --json` (the command, run as a user
    runs it).
    """
    cols = evaluate_batch(_grid([2.5e-4], outputs=("first_mode", "first_mode_damping",
                                                   "peak_stress_ratio"), input=2e-6), 0, 1)
    out = subprocess.run([sys.executable, "-m", "flexure_sim.cli", "modes", "microstage",
                          "--input", "2e-6", "--json"], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120, check=True)
    modes = json.loads(out.stdout)
    assert cols["first_mode"][0] == modes["undamped_frequencies_hz"][0]
    assert cols["first_mode_damping"][0] == modes["modal_damping_ratios"][0]
    static = subprocess.run([sys.executable, "-m", "flexure_sim.cli", "simulate", "microstage",
                             "--drive", "step:2e-6", "--static", "--json"],
                            capture_output=True, text=True, timeout=120, check=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    table = json.loads(static.stdout)["hinge_stress"]
    assert cols["peak_stress_ratio"][0] == max(h["ratio"] for h in table.values())


# ------------------------------------------------------------------------------ the command
def test_a_design_that_fails_is_recorded_and_the_study_goes_on(tmp_path):
    study = tmp_path / "grid.yaml"
    study.write_text(yaml.safe_dump({"mechanism": "microstage", "outputs": ["gain"],
                                     "batch_size": 2,
                                     "parameters": [{"path": "stiffness_models.notch.h",
                                                     "values": [2.5e-4, -1e-4, 3e-4]}]}))
    res = _cli(study, "-o", tmp_path / "out.parquet", "--workers", "1", "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["failed"] == 1
    table = pq.read_table(tmp_path / "out.parquet").to_pydict()
    assert table["sample"] == [0, 1, 2]
    assert table["status"] == ["ok", "failed", "ok"]
    assert "stiffness_models.notch.h: must be positive" in table["error"][1]
    assert math.isnan(table["gain"][1]) and table["gain"][0] == pytest.approx(STAGE_GAIN, rel=1e-4)
    assert not (tmp_path / "out.parquet.parts").exists()
    about = json.loads(pq.read_schema(tmp_path / "out.parquet").metadata[b"flexure_sim.study"])
    assert about["units"] == {"gain": ""} and about["samples"] == 3 and about["seed"] is None
    assert about["parameters"][0]["paths"] == ["stiffness_models.notch.h"]
    for png in ("out_tornado.png", "out_histograms.png"):
        assert (tmp_path / png).stat().st_size > 1000


def test_a_bad_study_file_gets_one_line_naming_the_key(tmp_path):
    study = tmp_path / "bad.yaml"
    study.write_text("mechanism: microstage\noutputs: [gain]\nparameters:\n"
                     "  - {path: stiffness_models.notch.h, normal: {std: 1.0e-6}}\n"
                     "seed: 1\nsample: 10\n")
    res = _cli(study, "-o", tmp_path / "out.parquet", cwd=tmp_path)
    assert res.returncode == 1
    assert res.stderr.strip().splitlines() == [
        f"flexure-sim sweep: error: {study}: sample: unknown key (allowed: batch_size, "
        "description, "
        "input, mechanism, name, outputs, parameters, samples, seed, space, step)"]


@pytest.mark.slow
def test_ctrl_c_keeps_finished_batches_and_resume_completes_the_study(tmp_path):
    study = _small_stage_study(tmp_path, samples=120, batch_size=10)
    reference = sweep.run_study(load_study(study, OUTPUTS), tmp_path / "ref.parquet", workers=1)
    out = tmp_path / "out.parquet"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    stderr = _OneLineAhead()
    proc = subprocess.Popen([sys.executable, "-m", "flexure_sim.cli", "sweep", str(study),
                             "-o", str(out), "--workers", "1"], cwd=tmp_path, env=env,
                            stderr=stderr.write_end)
    stderr.started()
    first = stderr.line()  # printed once the first batch is stored
    assert first.startswith("flexure-sim sweep: 10/120 designs"), first
    proc.send_signal(signal.SIGINT)  # the child can store at most two more batches before it
    rest = stderr.finish(proc, timeout=60)
    assert proc.returncode == 130
    assert "interrupted: the finished batches are kept" in rest and "Traceback" not in rest
    kept = sorted(p.name for p in (tmp_path / "out.parquet.parts").glob("part-*.parquet"))
    assert kept and kept[0] == "part-000000.parquet" and len(kept) < 12
    assert not out.exists()

    again = _cli(study, "-o", out, "--workers", "1", cwd=tmp_path)
    assert again.returncode == 2 and "continue it with --resume" in again.stderr
    resumed = _cli(study, "-o", out, "--workers", "1", "--resume", "--json", cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr
    assert pq.read_table(out).equals(reference)


@pytest.mark.slow
def test_unreachable_scheduler_and_a_directory_as_output_get_one_line(tmp_path):
    study = _small_stage_study(tmp_path, samples=20, batch_size=10)
    env = {**os.environ, "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "2s"}
    res = _cli(study, "-o", tmp_path / "out.parquet", "--scheduler", "tcp://127.0.0.1:1",
               cwd=tmp_path, env=env)
    assert res.returncode == 1
    assert res.stderr.strip().splitlines() == [
        "flexure-sim sweep: error: Timed out trying to connect to tcp://127.0.0.1:1 after 2 s"]
    # the run that never got a batch leaves nothing that would need --resume
    again = _cli(study, "-o", tmp_path / "out.parquet", "--workers", "1", "--no-plots",
                 cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    (tmp_path / "adir").mkdir()
    res = _cli(study, "-o", tmp_path / "adir", "--workers", "1", cwd=tmp_path)
    assert res.returncode == 2
    assert res.stderr == (f"flexure-sim sweep: error: {tmp_path / 'adir'}: is a directory "
                          "(the output is one Parquet file)\n")


@pytest.mark.slow
def test_ctrl_c_at_a_terminal_stops_a_local_cluster_study_cleanly(tmp_path):
    """
    Ctrl-C at a terminal signals the whole foreground process group.

    The workers of the LocalCluster ignore it (no KeyboardInterrupt tracebacks), the command stops
    the study and keeps the finished batches.
    """
    study = _small_stage_study(tmp_path, samples=400, batch_size=10)
    out = tmp_path / "out.parquet"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    stderr = _OneLineAhead()
    proc = subprocess.Popen([sys.executable, "-m", "flexure_sim.cli", "sweep", str(study),
                             "-o", str(out), "--workers", "2"], cwd=tmp_path, env=env,
                            stderr=stderr.write_end, start_new_session=True)
    stderr.started()
    first = stderr.line()  # printed once the first batch is stored
    assert first.startswith("flexure-sim sweep: 10/400 designs"), first
    os.killpg(proc.pid, signal.SIGINT)  # what the terminal does; the study cannot end first
    rest = stderr.finish(proc, timeout=120)
    assert proc.returncode == 130
    assert "Traceback" not in rest and "KeyboardInterrupt" not in rest, rest
    assert rest.strip().endswith("continue with --resume")
    assert list((tmp_path / "out.parquet.parts").glob("part-*.parquet"))


def test_resume_refuses_the_parts_of_another_study(tmp_path):
    study = _small_stage_study(tmp_path, samples=20, batch_size=10)
    out = tmp_path / "out.parquet"
    sweep.PartStore(out, load_study(study, OUTPUTS), resume=False)
    other = load_study(_small_stage_study(tmp_path, samples=20, batch_size=10, seed=5), OUTPUTS)
    with pytest.raises(sweep.SweepError, match="written for another study"):
        sweep.PartStore(out, other, resume=True)


@pytest.mark.slow
def test_same_seed_gives_bit_identical_parquet_with_one_and_two_workers(tmp_path):
    study = _small_stage_study(tmp_path, samples=200, batch_size=25)
    one = _cli(study, "-o", tmp_path / "one.parquet", "--workers", "1", "--no-plots", cwd=tmp_path)
    two = _cli(study, "-o", tmp_path / "two.parquet", "--workers", "2", "--no-plots", cwd=tmp_path)
    assert one.returncode == 0 and two.returncode == 0, (one.stderr, two.stderr)
    a, b = pq.read_table(tmp_path / "one.parquet"), pq.read_table(tmp_path / "two.parquet")
    assert a.num_rows == 200 and a.equals(b)
    for name in a.column_names[1:-2]:  # every float column, bit for bit
        assert a.column(name).to_numpy().tobytes() == b.column(name).to_numpy().tobytes()
    assert set(a.column("status").to_pylist()) == {"ok"}


# ------------------------------------------------------------------------ on a Dask cluster
@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        with Client(cluster) as c:
            yield c


@pytest.mark.slow
def test_a_worker_killed_mid_study_loses_and_duplicates_no_rows(tmp_path, client):
    study = load_study(_small_stage_study(tmp_path, samples=200, batch_size=20), OUTPUTS)
    reference = pa.Table.from_pydict(evaluate_batch(study, 0, 200), schema=sweep.schema(study))
    killed: dict = {}

    def kill_a_busy_worker(progress):
        if killed:
            return
        processing = client.processing()
        pids = client.run(os.getpid)
        victim = max(processing, key=lambda addr: len(processing[addr]))
        killed.update(tasks=list(processing[victim]), pid=pids[victim])
        os.kill(pids[victim], signal.SIGKILL)

    table = sweep.run_study(study, tmp_path / "out.parquet", client=client,
                            on_batch=kill_a_busy_worker)
    assert killed["tasks"], "the killed worker had no unfinished batch"
    assert killed["pid"] not in client.run(os.getpid).values()
    assert table.column("sample").to_pylist() == list(range(200))
    assert table.equals(reference)
    assert pq.read_table(tmp_path / "out.parquet").equals(reference)


@pytest.mark.slow
def test_an_existing_scheduler_by_address(tmp_path, client):
    study = _small_stage_study(tmp_path, samples=40, batch_size=10)
    res = _cli(study, "-o", tmp_path / "out.parquet", "--scheduler", client.scheduler.address,
               "--json", "--no-plots", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    st = load_study(study, OUTPUTS)
    assert pq.read_table(tmp_path / "out.parquet").equals(
        pa.Table.from_pydict(evaluate_batch(st, 0, 40), schema=sweep.schema(st)))


# ------------------------------------------------------------------------------ summary
def test_summary_statistics_and_correlation_ranking():
    """Against numpy's corrcoef and percentiles on a table made here: y = 3 x1 - x2 + noise."""
    study = study_from_dict({"mechanism": "microstage", "outputs": ["gain"], "samples": 3,
                             "seed": 0,
                             "parameters": [{"name": "x1", "path": "stiffness_models.notch.h",
                                             "normal": {"std": 1e-6}},
                                            {"name": "x2", "path": "stiffness_models.notch.D",
                                             "normal": {"std": 1e-6}}]}, "s.yaml", OUTPUTS)
    rng = np.random.default_rng(1)
    x1, x2 = rng.standard_normal(500), rng.standard_normal(500)
    y = 3 * x1 - x2 + 0.1 * rng.standard_normal(500)
    status = ["ok"] * 499 + ["failed"]
    y[-1] = np.nan
    table = pa.table({"sample": np.arange(500), "x1": x1, "x2": x2, "gain": y, "status": status,
                      "error": [""] * 499 + ["SolverError: x"]})
    s = sweep_summary.summarize(table, study)
    g = s["outputs"]["gain"]
    assert s["failed"] == 1 and g["count"] == 499
    assert g["mean"] == pytest.approx(np.mean(y[:-1]))
    assert g["std"] == pytest.approx(np.std(y[:-1], ddof=1))
    assert g["p01"] == pytest.approx(np.percentile(y[:-1], 1))
    assert [c["parameter"] for c in g["correlation"]] == ["x1", "x2"]
    assert g["correlation"][1]["r"] == pytest.approx(np.corrcoef(x2[:-1], y[:-1])[0, 1], rel=1e-12)
