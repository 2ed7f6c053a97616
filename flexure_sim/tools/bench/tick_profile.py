"""
Profile of the stage node's tick: where its time goes, next to the engine work it carries.

A real ``StageNode`` in this process (real-time mode, real publishers, the recorder process
writing a temporary file), its stepping thread stopped so that this thread ticks it back to
back: each part of a tick as the loop times it (publish/diagnostics.py ``TICK_PARTS``: intake,
engine, report, pack, record, publish), the whole tick, and in the same process the engine's
own cost per step over a long run (``Simulation.step(n)`` of 10,000 steps, the bench's
figure). The **overhead factor** is the tick's time over its engine steps at that cost,
``tick / (steps per tick x per-step time)``: machine-independent, 1 for a tick that were all
physics. For comparison, the routes the tick no longer takes: the ``Snapshot`` and message-by-
message packing (``StageInterface.encode``). No DDS traffic reaches another process (no
subscriber); diagnostics and display ticks are not in the timed parts. The front end is
``python -m flexure_sim.tools.bench.measure --profile``.
"""
from __future__ import annotations

import os
import random
import tempfile
import time
from typing import Any

from flexure_sim.node.publish.diagnostics import TICK_PARTS

#: Engine steps of the per-step reference run (one call, as the bench's step cost).
REFERENCE_STEPS = 10_000


class _Parts:
    """Stands in for the loop's diagnostics while profiling: sums every tick's parts."""

    def __init__(self) -> None:
        self.window = self
        self.ticks = 0
        self.sums = [0.0] * (len(TICK_PARTS) + 1)

    def add(self, *times: float) -> None:
        self.ticks += 1
        for k, t in enumerate(times):
            self.sums[k] += t

    def publish(self, _stamp: int) -> None:
        """Diagnostics are not part of the profile."""


def engine_step_us(mechanism: Any, sim_step: float, steps: int = REFERENCE_STEPS,
                   repeats: int = 3) -> float:
    """Return the engine's wall time per step (us) over ``steps`` in one call, best of repeats."""
    from flexure_sim.engine.solver.simulation import Simulation
    from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL

    sim = Simulation(mechanism, dt=sim_step, relinearize_tol=RELINEARIZE_TOL, energy=False)
    if sim.model.drives:
        sim.set_command([0.5 * (d.stroke[0] + d.stroke[1]) for d in sim.model.drives]
                        if len(sim.model.drives) > 1 else 0.5 * sum(sim.model.drives[0].stroke))
    sim.step(100)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        sim.step(steps)
        best = min(best, time.perf_counter() - t0)
    return 1e6 * best / steps


def profile(rate: float, sim_step: float, ticks: int = 3000,
            mechanism: str = "microstage", monitor_rate: float = 0.0) -> dict[str, float]:
    """
    Return the tick's parts (us, means over ``ticks``), the engine's per-step cost and their ratio.

    Every tick takes a new drive command (a closed loop's), within the slew of a step.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from flexure_sim.node.stage.shell import StageNode

    context = Context()
    rclpy.init(context=context, domain_id=random.randint(1, 100))
    cwd = os.getcwd()
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)
        node = None
        try:
            node = StageNode(context=context, parameter_overrides=[
                Parameter("mechanism", value=mechanism), Parameter("time_mode", value="realtime"),
                Parameter("publish_rate", value=float(rate)),
                Parameter("sim_step", value=float(sim_step)),
                Parameter("monitor_rate", value=float(monitor_rate)),
                Parameter("display_rate", value=0.0), Parameter("record", value=True)])
            loop = node.loop
            loop.stop(10.0)  # this thread ticks it from now on
            loop.pacer = None
            parts = _Parts()
            loop.diagnostics = parts  # type: ignore[assignment]
            filt = loop.filter
            commands = [0.0]

            def command() -> None:  # a closed loop's new command, a few nm from the last
                if filt is not None and hasattr(filt, "submit_many"):
                    commands[0] = 1.0e-6 + 1e-9 * (len(commands) % 7)
                    filt.submit_many([commands[0]])

            for _ in range(300):
                command()
                loop.tick()
            parts.__init__()
            for _ in range(ticks):
                command()
                loop.tick()
            n = parts.ticks
            for name, total in zip((*TICK_PARTS, "tick"), parts.sums):
                out[f"{name}_us"] = 1e6 * total / n
            out["steps_per_tick"] = loop.n_steps
            out["topics_per_tick"] = len(loop.interface.tick_topics)
            out.update(_old_routes(loop))
        finally:
            if node is not None:
                node.shutdown()
                node.destroy_node()
            rclpy.try_shutdown(context=context)
            os.chdir(cwd)
    out["engine_step_us_reference"] = engine_step_us(node.mechanism, sim_step)
    out["overhead_factor"] = out["tick_us"] / (out["steps_per_tick"]
                                               * out["engine_step_us_reference"])
    out["engine_ratio"] = out["engine_us"] / (out["steps_per_tick"]
                                              * out["engine_step_us_reference"])
    out["tick_budget_us"] = 1e6 / rate
    return out


def _old_routes(loop: Any, n: int = 300) -> dict[str, float]:
    """Time the Snapshot and message-by-message packing, what the tick replaced (us)."""
    sim = loop.sim
    t0 = time.perf_counter()
    for _ in range(n):
        snap = sim.snapshot()
    t1 = time.perf_counter()
    for k in range(n):
        loop.interface.encode(snap, k)
    t2 = time.perf_counter()
    return {"snapshot_route_us": 1e6 * (t1 - t0) / n, "encode_route_us": 1e6 * (t2 - t1) / n}
