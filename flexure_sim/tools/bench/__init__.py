"""
Measurements: flexure-sim bench, the node's timing harness, the closed loop, the flood.

- ``benchmarks``: Benchmarks.
- ``closed_loop``: The closed loop at 1 kHz, measured.
- ``engine_bench``: Engine benchmarks of ``flexure-sim bench``: the stage's step response, step
  cost, static sweep.
- ``flood``: A drive-command flood from a process of its own, as a misbehaving controller would
  send it.
- ``spatial_bench``: Spatial engine benchmarks of ``flexure-sim bench``: 3-D stepping speed at the
  planar accuracy.
- ``measure``: Measure the stage node: real-time factor in fast mode and missed ticks in real-time
  mode.
- ``study_bench``: Analysis and sweep benchmarks of ``flexure-sim bench``: linearisation,
  sensitivities, Dask sweep.
- ``tick_profile``: Profile of one stage_node tick: where its time goes, in this process and
  without DDS traffic.
"""
