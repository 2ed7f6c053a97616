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
        # Step by step only while the ramp lasts: once the applied target reaches the
        # command, the rest of the tick is one compiled call (the same states as one step
        # at a time). A controller's new command every tick is usually within one step's
        # slew, so a tick is then one set_command and one step(n), not n of each (which
        # cost ~0.25 ms of Python per tick and made real-time ticks late).
        remaining = n_steps
        while remaining:
            sim.set_command(filt.advance(dt))
            if filt.settled:
                sim.step(remaining)
                break
            sim.step(1)
            remaining -= 1
