"""
Measurements: flexure-sim bench, the node's timing harness, the closed loop, the flood, the floor.

- ``benchmarks``: Benchmarks.
- ``closed_loop``: The closed loop, measured.
- ``engine_bench``: Engine benchmarks of ``flexure-sim bench``: the stage's step response, step
  cost, static sweep.
- ``flood``: A drive-command flood from a process of its own, as a misbehaving controller would
  send it.
- ``node_bench``: ``flexure-sim bench --node``: the stage node's figures, from one run.
- ``spatial_bench``: Spatial engine benchmarks of ``flexure-sim bench``: 3-D stepping speed at the
  planar accuracy.
- ``measure``: Measure the stage node: real-time factor in fast mode and missed ticks in real-time
  mode.
- ``pingpong``: The floor of a closed loop through rclpy on this machine: a bare ping-pong
  between two processes.
- ``study_bench``: Analysis and sweep benchmarks of ``flexure-sim bench``: linearisation,
  sensitivities, Dask sweep.
- ``tick_profile``: Profile of the stage node's tick: where its time goes, next to the engine work
  it carries.
"""
