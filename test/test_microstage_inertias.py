"""
The stage's masses and inertias are microstage.sci's geometry formulas (issue 30 item 14).

The formulas of the dissertation's Appendix A (microstage.sci), written out here with density
2.8e3 kg/m^3 (which reproduces the printed masses of eqs. 6.8-6.13) and plate thickness 0.02 m:
each body's mass and inertia in every file that describes the stage agree with them to double
precision (they were rounded to 6 digits: body4 -2.9e-6, body6 +2.0e-6 relative).
"""
import pytest

from flexure_sim.engine.mechanism.loader import load_mechanism

RHO, T = 2.8e3, 0.02


def sci_bodies() -> dict:
    """Return {body: (mass, inertia)} as microstage.sci computes them (Appendix A)."""
    m1 = RHO * (0.038 * 0.012 + 0.012 * 0.056 + 0.006 * 0.024) * T
    ma, mb, mc = RHO * 0.005 * 0.010 * T, RHO * 0.021 * 0.006 * T, RHO * 0.014 * 0.010 * T / 2
    i2 = (ma * (0.005**2 + 0.010**2) / 12 + ma * (0.001**2 + 0.018**2)
          + mb * (0.006**2 + 0.021**2) / 12 + mb * (0.002**2 + 0.008**2)
          + mc * (0.006**2 + 0.009**2) / 12 + mc * (0.003**2 + 0.006**2))
    m3 = RHO * 0.017 * 0.005 * T * 2
    i3 = m3 * (0.017**2 + 0.005**2) / 12 + m3 * (0.0025**2 + 0.0075**2)
    m4 = RHO * 0.010 * 0.028 * T
    m6 = RHO * 0.014 * 0.010 * T
    return {
        "body1": (m1, m1 * (0.030**2 + 0.024**2) / 12),
        "body2": (ma + mb + mc, i2),
        "body3": (m3, i3),
        "body4": (m4, m4 * (0.028**2 + 0.010**2) / 12),
        "body5": (m3, i3),
        "body6": (m6, m6 * (0.007**2 + 0.05**2) / 12),   # as microstage.sci writes it
    }


@pytest.mark.parametrize("name", ["microstage", "microstage_realistic",
                                  "config/examples/microstage_polynomial_a.yaml"])
def test_every_stage_file_has_microstage_sci_masses_and_inertias(name):
    from conftest import ROOT

    mech = load_mechanism(ROOT / name if name.endswith(".yaml") else name)
    want = sci_bodies()
    for body in mech.bodies:
        mass, inertia = want[body.name]
        assert body.mass == pytest.approx(mass, rel=1e-15), body.name
        assert body.inertia == pytest.approx(inertia, rel=1e-15), body.name
