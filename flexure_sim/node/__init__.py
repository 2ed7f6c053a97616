"""
The ROS 2 shell around the engine (rclpy); holds no physics.

- ``stage``: the stage node, its main loop and the paced stepping thread;
- ``params``: its parameters as data, their checks and declaration;
- ``inputs``: drive commands in;
- ``publish``: what it publishes and how the messages are packed;
- ``record``: its recordings, written by a helper process;
- ``apps``: other nodes (demo driver, PI controller, replay).
"""
