"""
The reference figures the tests assert, each written once with its source.

The micropositioning stage (``config/microstage.yaml``) is the dissertation's Chapter 6 stage
(lines 5495-6209 of /work/shared/reference/twistor-flexure-dissertation.txt, its Scilab model
``microstage.sci`` in Appendix A). A figure here comes from the dissertation, from a formula
written out, or from an independent reimplementation of the same model; the two without
such a source (the first mode, the stroke limit) say so. The tolerances stay in the tests:
each states how closely its command, output or file has to reproduce the figure.
"""

# ---------------------------------------------------------------- the notch hinge (Ch. 5, 6)

#: Notch hinge of the stage (D 3 mm, h 0.25 mm, t 20 mm, E 69 GPa, nu 0.33), eqs. 5.27-5.33
#: (``notch_stiff.sci``): rotational stiffness Ko, N m/rad, as the dissertation prints it
#: (Chapter 6, eqs. 6.2-6.3).
NOTCH_KO = 2.5096
#: Its translational stiffness Kt = diag(KX, KY), N/m, along the hinge's x (axial) and y
#: (shear) axes (Chapter 6, eqs. 6.2-6.3).
NOTCH_KX = 1.588e8
NOTCH_KY = 1.661e7

# ---------------------------------------------------------------- the stage (Ch. 6)

#: The static input at joint a (body 6, horizontal), m: 1.35 um (Chapter 6; the OCR's one
#: "1.35 mm" is a misprint).
STAGE_INPUT = 1.35e-6

#: Output / input displacement gain of the stage at STAGE_INPUT. The dissertation prints 27.8
#: (37.5 um, read off Figure 6.3); the converged answer of the model as ``microstage.sci``
#: specifies it is 27.628 (37.298 um): an independent reimplementation of that model agrees
#: to 7e-5 (README, "What it reproduces").
STAGE_GAIN = 27.628

#: Compression of joint a at STAGE_INPUT, m: 192.2 nm from the same independent
#: reimplementation (to the 3 digits quoted; the dissertation's "about 150 nm" is read off
#: Figure 6.4).
JOINT_A_COMPRESSION = 192.2e-9

#: Rigid-lever gain: the lever arms alone, (41/9) (24/3) = 36.4 (Chapter 6), which
#: translationally rigid hinges recover and the hinges' compliance brings down.
RIGID_LEVER_GAIN = 41 / 9 * 24 / 3

#: The stage's first undamped mode, Hz. No independent source: the dissertation gives no
#: modes. 300.6 Hz is the figure docs/analyses.md and the README publish (the Bode phase passes
#: -90 degrees there), pinned here so that a change to it shows; test_linear.py checks the
#: frequency response at that mode against a time-domain sine response (step 2 us).
FIRST_MODE_HZ = 300.6

#: Drive input at which the first hinge (c) reaches the yield strength of 6061-T6, m. No
#: independent source: the figure docs/analyses.md publishes (``simulate --stroke-limit``),
#: pinned here so that a change to it shows; it is about 2 um / 0.1198, the peak stress ratio
#: at full stroke, as stress grows nearly linearly with the input.
STROKE_LIMIT = 16.70e-6
