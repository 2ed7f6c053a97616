"""flexure_sim: planar flexure mechanisms with the twistor-based potential energy method.

Layers, top-down (each imports only the ones above it):
  kinematics  -> hinge_laws (+ stiffness) -> mechanism (+ config) -> drive -> assembly -> solver
  recording, node, tools, cli build on the engine; the engine never imports ROS.
"""
__version__ = "0.1.0"
