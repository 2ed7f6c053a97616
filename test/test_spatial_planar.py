"""
Planar mechanisms in the spatial engine: today's in-plane results, no out-of-plane motion.

The reference is the planar engine itself (``solver.simulation``, ``analysis.linear``): the
same file opened in 3-D must give its in-plane coordinates to 1e-12 (relative to the
mechanism's size, 1e-12 rad on the rotations) and exactly zero out-of-plane coordinates under
in-plane loads, in statics, in the linear model and in stepping.
"""
import copy

import numpy as np
import pytest

from flexure_sim.engine.analysis import linear as planar_linear
from flexure_sim.engine.analysis import spatial_linear
from flexure_sim.engine.analysis.linear_response import gain_matrix
from flexure_sim.engine.mechanism.loader import load_mechanism, mechanism_from_dict
from flexure_sim.engine.mechanism.loader import resolve_mechanism_path
from flexure_sim.engine.mechanism.spatial_loader import load_spatial, spatial_from_dict
from flexure_sim.engine.mechanism.yaml_files import read_yaml
from flexure_sim.engine.mechanism.values import ConfigError
from flexure_sim.engine.solver.simulation import Simulation
from flexure_sim.engine.solver.spatial_simulation import SpatialSimulation

IN_PLANE, OUT_OF_PLANE = [0, 1, 5], [2, 3, 4]


def compare(z3, z2, z0_2, scale):
    """Return the largest in-plane difference (scaled) and the out-of-plane coordinates."""
    Z3, Z2 = z3.reshape(-1, 6), z2.reshape(-1, 3)
    theta0 = z0_2.reshape(-1, 3)[:, 2]
    diff = np.abs(Z3[:, IN_PLANE] - np.column_stack([Z2[:, 0], Z2[:, 1], Z2[:, 2] - theta0]))
    diff[:, :2] /= scale
    return diff.max(), Z3[:, OUT_OF_PLANE]


@pytest.mark.parametrize("name, u", [("microstage", 1.35e-6), ("xy_stage", [1e-5, -4e-6])])
def test_static_equilibria_are_the_planar_ones(name, u):
    planar = Simulation(load_mechanism(name))
    spatial = SpatialSimulation(load_spatial(name))
    st2, st3 = planar.static(u), spatial.static(u)
    diff, out = compare(st3.z, st2.z, planar.z0, spatial.model.length_scale)
    assert diff < 1e-12
    assert np.all(out == 0.0)
    assert np.allclose(spatial.model.output_values(st3.z), planar.model.output_values(st2.z),
                       rtol=0, atol=1e-12 * spatial.model.length_scale)


def test_xy_stage_static_gains_are_the_planar_ones():
    planar = Simulation(load_mechanism("xy_stage"))
    spatial = SpatialSimulation(load_spatial("xy_stage"))
    assert np.allclose(spatial.static_gain(), planar.static_gain(), rtol=1e-12,
                       atol=1e-12 * np.abs(planar.static_gain()).max())


def test_microstage_modes_contain_the_planar_modes_and_the_in_plane_stiffness():
    planar = planar_linear.linearize(Simulation(load_mechanism("microstage")))
    spatial = spatial_linear.linearize(SpatialSimulation(load_spatial("microstage")).model)
    f2 = planar_linear.modes(planar).frequencies
    f3 = spatial_linear.modes(spatial).frequencies
    for f in f2:
        assert np.min(np.abs(f3 - f)) <= 1e-9 * f
    # the in-plane block of the 3-D stiffness is the planar one, the coupling exactly zero
    k3 = spatial.stiffness
    free = list(spatial.free)
    inplane = [i for i, k in enumerate(free) if k % 6 in IN_PLANE]
    other = [i for i, k in enumerate(free) if k % 6 not in IN_PLANE]
    assert np.allclose(k3[np.ix_(inplane, inplane)], planar.stiffness, rtol=0,
                       atol=1e-12 * np.abs(planar.stiffness).max())
    assert np.all(k3[np.ix_(inplane, other)] == 0.0)
    # the linear model's in-plane outputs: the planar gain and frequency response
    g2, g3 = gain_matrix(planar), gain_matrix(spatial)
    assert g3[0, 0] == pytest.approx(g2[0, 0], rel=1e-12)


def test_stepping_the_stage_gives_the_planar_motion_and_no_out_of_plane_motion():
    planar = Simulation(load_mechanism("microstage"))
    spatial = SpatialSimulation(load_spatial("microstage"))
    for sim in (planar, spatial):
        sim.set_command(1.35e-6)
        sim.step(150)
    diff, out = compare(spatial.state.z, planar.state.z, planar.z0, spatial.model.length_scale)
    assert diff < 1e-12
    assert np.all(out == 0.0)
    assert np.all(spatial.state.v.reshape(-1, 6)[:, OUT_OF_PLANE] == 0.0)
    assert spatial.snapshot().outputs["output"] == pytest.approx(
        planar.snapshot().output, rel=1e-11)


def fourbar_with_a_torque(law):
    """
    Return the cantilever four-bar with its crank turned by a torque.

    config/fourbar_cantilever.yaml, with a force drive on theta instead of the prescribed rate.
    """
    doc = copy.deepcopy(read_yaml(resolve_mechanism_path("fourbar_cantilever"), ConfigError))
    doc["defaults"]["law"] = law
    doc["constraints"][1] = {"type": "force", "name": "torque", "body": "link2",
                             "axis": "theta", "response_time": 1e-3, "stroke": [-1, 1],
                             "slew_rate": 1}
    return doc


@pytest.mark.parametrize("law", ["twistor", "twist"])
def test_large_in_plane_rotations_of_a_four_bar_are_the_planar_ones(law):
    """
    A torque turns the crank by 21 degrees: the planar result, nothing out of the plane.

    Large rotations of every link and hinge, the same in both engines.
    """
    doc = fourbar_with_a_torque(law)
    planar = Simulation(mechanism_from_dict(doc))
    spatial = SpatialSimulation(spatial_from_dict(doc))
    st2 = planar.static(0.2)
    st3 = spatial.static(0.2)
    assert abs(st2.z[5]) > np.deg2rad(15)
    diff, out = compare(st3.z, st2.z, planar.z0, spatial.model.length_scale)
    assert diff < 1e-12
    assert np.all(out == 0.0)
