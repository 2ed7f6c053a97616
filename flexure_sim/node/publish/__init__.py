"""
What the stage node publishes: its interface, message packing, display, diagnostics.

- ``cdr``: Precompiled CDR packers for the few fixed-layout messages the stage node publishes.
- ``diagnostics``: The stage node's ``diagnostics`` topic.
- ``diagnostics_msg``: The diagnostics message of the stage node, and the stamp and value formats
  it shares.
- ``display``: What the stage node publishes for viewers (RViz, Foxglove) at its display rate.
- ``interface``: The stage node's ROS interface as data.
- ``marker_cdr``: The stage's ``visualization_msgs/MarkerArray`` packed straight to CDR.
- ``markers``: The stage drawn for RViz and Foxglove: a ``visualization_msgs/MarkerArray`` per
  display tick.
- ``reference_messages``: The stage node's tick messages as rclpy message objects.
- ``tick_frame``: A tick's messages packed in one compiled call, into the recorder's batch frame.
"""
