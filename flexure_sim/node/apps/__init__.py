"""
Other nodes: the demo driver, the PI controller, the replay node.

- ``demo_drive``: A small rclpy node that drives a running ``stage_node`` through a demo profile of
  steps.
- ``pi_controller``: ``pi_controller``: an example controller closing the loop around
  ``stage_node``.
- ``replay``: ``flexure-sim replay RUN.mcap`` (also ``ros2 run flexure_sim replay RUN.mcap``).
"""
