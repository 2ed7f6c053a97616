"""
The designer's analyses: linearisation, modes, FRF, sensitivities, sweeps.

- ``linear``: Exact linearisation about a static equilibrium, with any number of drives.
- ``linear_response``: What the exact linear model (``linear.LinearModel``) answers: modes, poles,
  FRF, static gain.
- ``parametric``: The mechanism's hinge forces as a function of its coordinates *and* its design
  parameters.
- ``spatial_linear``: Exact linearisation of a spatial mechanism about a static equilibrium:
  modes, FRF, gains.
- ``sensitivity``: Exact first and second design sensitivities by hyper-dual numbers.
- ``study``: Study files: design sweeps (a grid) and Monte Carlo tolerance studies of one
  mechanism.
- ``study_checks``: A study's checks against its base mechanism: the drive input, and the outputs
  it can give.
"""
