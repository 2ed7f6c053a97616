"""
Actuators and sensors on a mechanism: the piezo stack and the output sensor.

- ``piezo``: A piezo stack actuator: amplifier lag, Bouc-Wen hysteresis, Kelvin-Voigt creep, stack
  stiffness.
- ``piezo_run``: The piezo actuator (engine/actuators/piezo.py) alone against a linear spring load.
- ``piezo_steps``: The piezo actuators of a ``Model`` over n steps of a held command, in one
  compiled call.
- ``sensor``: A displacement sensor on the mechanism's output (a capacitive gauge).
"""
