"""
The designer's commands: modes, frf, linearize, sensitivity, sweep, fit, piezo-loop.

- ``fit``: ``flexure-sim fit``: fit a polynomial hinge law to measured wrenches (dissertation Ch.
  7).
- ``linear_commands``: ``flexure-sim modes | frf | linearize``: the linear analyses
  (engine/analysis/linear.py).
- ``linear_export``: ``flexure-sim linearize -o FILE``: the linear model written as .npz, .mat
  or .json.
- ``linear_plots``: The figures and tables of ``flexure-sim modes | frf``
  (tools/design/linear_commands.py).
- ``piezo_loop``: ``flexure-sim piezo-loop``: the hysteresis loop of a drive's piezo
  (engine/actuators/piezo.py).
- ``sensitivity_command``: ``flexure-sim sensitivity MECH --wrt PARAM[,PARAM...] --of
  OUTPUT[,OUTPUT...]``.
- ``sweep``: ``flexure-sim sweep STUDY.yaml -o results.parquet``: design sweeps and Monte Carlo
  studies.
- ``sweep_outputs``: What a sweep computes for each design: the output registry and the batch
  evaluation.
- ``sweep_run``: Running a study.
- ``sweep_summary``: Summary of a sweep's results.
"""
