"""
The stage node: the rclpy shell, its main loop and the paced stepping thread.

- ``cpu_latency``: A CPU wake-up latency request (Linux PM QoS), held while real-time stepping
  runs.
- ``engine_guard``: What the engine can follow.
- ``loop_parts``: What a stepping loop is built from: its parts and its settings (no ROS).
- ``main_loop``: stage_node's main loop: the executor spins until a shutdown or the stepping
  thread's end.
- ``overrun``: A visible warning when real-time ticks do not fit their period (no ROS).
- ``pacing``: Real-time pacing of the stage node's publish ticks against a steady clock (no ROS).
- ``polled``: Subscriptions read by the stepping thread at each tick instead of by the executor.
- ``qos_watch``: Incompatible QoS on the stage node's topics: counted, logged, shown in the
  diagnostics.
- ``requests``: Hand-over of work from the executor (services, parameter changes) to the stepping
  thread.
- ``shell``: `StageNode`: the rclpy node around the engine, a thin shell.
- ``stage_node``: ``stage_node``: the executable of the stage node (`shell.StageNode`).
- ``stepping_thread``: The stage node's stepping thread.
"""
