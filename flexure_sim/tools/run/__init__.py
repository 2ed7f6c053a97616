"""
Tools on recorded runs: info, analyse, plot, export.

- ``analyse``: ``flexure-sim analyse RUN.mcap``.
- ``analyse_drives``: ``flexure-sim analyse`` of a run with several drives or outputs: the gain
  matrix.
- ``export``: ``flexure-sim export RUN.mcap --csv DIR``.
- ``export_signals``: ``flexure-sim export RUN --csv DIR --signals``: the drives and outputs of a
  run in one table.
- ``gain_matrix``: Steps of several drives and the gain matrix they measure: pure functions on
  NumPy arrays.
- ``mechanism_reload``: The mechanism a recorded run simulated.
- ``plot``: ``flexure-sim plot RUN.mcap -o DIR``: PNG figures of a recorded run.
- ``plot_drives``: Figures of a run with several drives or outputs (``flexure-sim plot``; issue
  13).
- ``response_metrics``: Step-response metrics of one signal: settling time, overshoot, rise time,
  peak.
- ``run_channels``: The drives and outputs of a recorded run, by name, with their topics and units.
- ``run_info``: ``flexure-sim info RUN.mcap``.
- ``runlog``: A recorded run as typed time series, read in one streaming pass.
- ``series``: Time series of a recorded run, built message by message in compact arrays.
- ``simulate_limits``: ``flexure-sim simulate``'s hinge limits: stresses, the fatigue of a
  static cycle, the stroke limit.
- ``simulate_spatial``: ``flexure-sim simulate`` for 3-D mechanisms: a step response or the
  static equilibrium.
- ``step_analysis``: Step detection and step-response metrics: pure functions on NumPy arrays (no
  files, no ROS).
- ``timebase``: From log time to simulation time.
"""
