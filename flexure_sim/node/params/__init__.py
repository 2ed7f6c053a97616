"""
The stage node's parameters: the table as data, its checks, its declaration to ROS.

- ``checks``: Checks of the stage node's parameter values (pure Python, no side effects).
- ``declare``: The stage node's parameters declared to ROS.
- ``live``: The stage node's parameters while it runs: validation as a whole, and changes handed
  over.
- ``table``: The stage node's parameters as data (pure Python, no side effects).
"""
