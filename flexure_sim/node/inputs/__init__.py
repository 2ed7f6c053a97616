"""
Drive commands into the stage node: intake, checks, the drives they address.

- ``command_checks``: Validation of the piezo drive commands the stage node receives (pure Python,
  no ROS).
- ``command_intake``: Drive command intake of the stage node.
- ``drive_bank``: Several named drives in the stage node (pure Python, no ROS): parameters,
  validation, filters.
- ``drive_kind``: What a drive's command is, and its unit and limits in that unit (pure Python, no
  ROS).
"""
