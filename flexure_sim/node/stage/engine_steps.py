"""
The engine steps of one stage-node tick, following the drive filter's ramp (no ROS).

A tick advances the simulation (planar or spatial: ``step``, ``set_command`` and ``state``
are all it uses) by its steps with the drives' command filter's applied targets.
"""
from __future__ import annotations

from typing import Any


def advance(sim: Any, filt: Any, intake: Any, n_steps: int, dt: float) -> None:
    """
    Take a tick's ``n_steps`` engine steps of ``dt``, following the filter ``filt``'s ramp.

    ``filt``: the drives' command filter (None without a drive); ``intake``: the command
    intake that warns of rate-limited commands (None without a drive).
    """
    if filt is None:
        sim.step(n_steps)
        return
    if filt.begin_tick(n_steps * dt) and intake is not None:
        intake.warn_rate_limited()
    if filt.settled:
        if filt.differs(sim.state.command):
            sim.set_command(filt.applied)
        sim.step(n_steps)
    else:
        # While the ramp lasts each step holds the filter's next applied target; once it
        # reaches the command, that is held for the rest of the tick. A controller's new command
        # every tick is usually within one step's slew: one target, one set_command and one
        # step(n). A longer ramp is one call too where the simulation offers it
        # (``Simulation.step_commands``: the same states as one step at a time).
        ramp = [filt.advance(dt)]
        while not filt.settled and len(ramp) < n_steps:
            ramp.append(filt.advance(dt))
        if len(ramp) > 1 and hasattr(sim, "step_commands"):
            sim.step_commands(ramp, n_steps)
            return
        for i, command in enumerate(ramp):
            sim.set_command(command)
            sim.step(1 if i < len(ramp) - 1 else n_steps - i)
