"""
The compression hinge's compression does not depend on labels (issue 16 item 9).

Not on which body is called A, not on where the coincident hinge frames are put.
"""
import dataclasses

import numpy as np
import pytest

from flexure_sim.engine.kinematics import planar as kin
from flexure_sim.engine.mechanism.loader import load_mechanism, mechanism_from_dict
from flexure_sim.engine.laws.quadratic import QuadraticLaw
from flexure_sim.engine.solver.simulation import Simulation, stiffness_centre
from test_statics import DRIVEN_PLATFORM
from reference_figures import JOINT_A_COMPRESSION

U_IN = 1.35e-6


@pytest.fixture(scope="module")
def stage():
    return load_mechanism("microstage")


def _swap(h):
    return dataclasses.replace(h, a=h.b, b=h.a)


def _move_frames(h, R, p):
    """
    Both coincident frames of h moved to a*(R, p).

    b*(R, p), K and B transformed with the adjoint (Sections 3.3, 4.6): the same physical hinge.
    """
    def moved(f):
        pos = np.array(f.position) + kin.rot(f.angle) @ p
        return dataclasses.replace(f, position=(pos[0], pos[1]), angle=f.angle + kin.angle_of(R))
    law = h.law
    K, B = kin.transform_stiffness(law.K, R, p), kin.transform_stiffness(law.B, R, p)
    return dataclasses.replace(h, a=moved(h.a), b=moved(
        h.b), law=QuadraticLaw(law.coordinates, K, B))


def _with_hinge(mech, name, change):
    return dataclasses.replace(mech, hinges=tuple(
        change(h) if h.name == name else h for h in mech.hinges))


def test_stage_value_is_kept(stage):
    assert Simulation(stage).static(
        U_IN).snapshot.compression == pytest.approx(JOINT_A_COMPRESSION, abs=0.05e-9)


def test_swapping_the_bodies_of_the_compression_hinge_keeps_its_compression(stage):
    base = Simulation(stage).static(U_IN).snapshot.compression
    swapped = Simulation(_with_hinge(stage, "a", _swap))
    assert swapped.static(U_IN).snapshot.compression == pytest.approx(base, rel=1e-9)
    assert swapped.static_sweep([U_IN]).compressions[0] == pytest.approx(base, rel=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_moving_the_hinge_frames_keeps_the_compression(stage, seed):
    """Frames moved by up to ~5 mm and turned (529 nm instead of 192 nm before the fix)."""
    rng = np.random.default_rng(seed)
    R, p = kin.rot(rng.uniform(-3, 3)), rng.normal(size=2) * 3e-3
    base = Simulation(stage).static(U_IN).snapshot.compression
    moved = Simulation(_with_hinge(stage, "a", lambda h: _move_frames(h, R, p)))
    assert moved.static(U_IN).snapshot.compression == pytest.approx(base, rel=1e-7)


def test_dynamic_compression_is_label_free_too(stage):
    def move(h):
        return _move_frames(h, kin.rot(1.0), np.array([2e-3, 1e-3]))

    sims = [Simulation(stage), Simulation(_with_hinge(stage, "a", _swap)),
            Simulation(_with_hinge(stage, "a", move))]
    for s in sims:
        s.set_command(U_IN)
        s.step(10)
    values = [s.snapshot().compression for s in sims]
    assert values[1] == pytest.approx(values[0], rel=1e-9)
    assert values[2] == pytest.approx(values[0], rel=1e-6)


@pytest.mark.parametrize("swap", [False, True])
def test_a_hinge_between_ground_and_the_driven_body_takes_up_the_whole_input(swap):
    """Ground does not move: the hinge takes up all of the drive's u, whichever body is A."""
    mech = mechanism_from_dict(DRIVEN_PLATFORM)
    if swap:
        mech = _with_hinge(mech, "a", _swap)
    assert Simulation(mech).static(1e-6).snapshot.compression == pytest.approx(1e-6, rel=1e-9)


def test_stiffness_centre_is_where_the_coupling_vanishes():
    """A decoupled K moved to a frame (R, p) away has its centre at R^T (-p) in the new frame."""
    rng = np.random.default_rng(5)
    K = np.diag([2.5, 1.6e8, 1.7e7])
    for _ in range(5):
        R, p = kin.rot(rng.uniform(-3, 3)), rng.normal(size=2) * 1e-3
        centre = stiffness_centre(kin.transform_stiffness(K, R, p))
        assert centre == pytest.approx(R.T @ -p, rel=1e-9)


@pytest.mark.parametrize("change", ["swap", "move"])
def test_the_linear_model_measures_compression_as_the_engine_does(stage, change):
    """
    The state-space output 'compression' (engine/analysis/linear.py) is the engine's definition.

    Its static gain equals the engine's compression per unit input from two static solves (a
    central difference at 1.35 um), on a stage whose compression hinge is relabelled or has
    its frames moved: a second definition at the frame origins would differ there.
    """
    from flexure_sim.engine.analysis import linear

    R, p = kin.rot(0.7), np.array([2e-3, -1e-3])
    edit = _swap if change == "swap" else (lambda h: _move_frames(h, R, p))
    sim = Simulation(_with_hinge(stage, "a", edit))
    gain = linear.static_gain(linear.linearize(sim, U_IN, wrenches=False), ["compression"])[0]
    du = 1e-9
    fd = (sim.static(U_IN + du).snapshot.compression
          - sim.static(U_IN - du).snapshot.compression) / (2 * du)
    assert gain == pytest.approx(fd, rel=1e-5)
