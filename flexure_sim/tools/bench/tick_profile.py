"""
Profile of the stage node's tick: where its time goes, next to the engine work it carries.

A real ``StageNode`` in this process (real-time mode, real publishers, the recorder process
writing a temporary file), its stepping thread stopped so that this thread ticks it back to
back: each part of a tick as the loop times it (publish/diagnostics.py ``TICK_PARTS``: intake,
engine, report, pack, record, publish), the whole tick, and in the same process the engine's
own cost per step over a long run (``Simulation.step(n)`` of 10,000 steps, the bench's
figure). The **overhead factor** is the tick's time over its engine steps at that cost,
``tick / (steps per tick x per-step time)``: machine-independent, 1 for a tick that were all
physics. The engine's per-step cost depends on the motion: at rest a step's remainder
iteration converges in one sweep, while a stage following a closed loop's new command every
tick takes about two; so the engine part is also compared like for like, with the ticks' own
commands stepped in one call (``engine_step_us_moving``, ``engine_ratio_moving``; the
median tick's engine part, robust to a shared machine's preemptions, in
``engine_median_ratio_moving``). For comparison, the routes the tick no longer takes: the
``Snapshot`` and message-by-message packing (``StageInterface.encode``). Without the node,
the engine's cost per tick called tick by tick as the node calls it, against the same steps
in one call, at rest, under a closed loop and ramping (``call_costs``: ``call_*``). No DDS traffic
reaches another process (no subscriber); diagnostics and display ticks are not in the timed
parts. The front end is ``python -m flexure_sim.tools.bench.measure --profile``.
"""
from __future__ import annotations

import os
import random
import tempfile
import time
from typing import Any, Iterator

from flexure_sim.node.publish.diagnostics import TICK_PARTS

#: Engine steps of the per-step reference run (one call, as the bench's step cost).
REFERENCE_STEPS = 10_000


class _Parts:
    """Stands in for the loop's diagnostics while profiling: sums every tick's parts."""

    def __init__(self) -> None:
        self.window = self
        self.ticks = 0
        self.sums = [0.0] * (len(TICK_PARTS) + 1)
        #: Each tick's engine part (s): its median is robust to a shared machine's preemptions.
        self.engine: list[float] = []

    def add(self, *times: float) -> None:
        self.ticks += 1
        for k, t in enumerate(times):
            self.sums[k] += t
        self.engine.append(times[TICK_PARTS.index("engine")])

    def stages(self, _stamp: int) -> Iterator[None]:
        """Diagnostics are not part of the profile (``Diagnostics.stages``: none here)."""
        yield from ()


def closed_loop_command(tick: int) -> float:
    """Return a closed loop's new command at ``tick``: 1 um plus a few nm, unlike the last."""
    return 1.0e-6 + 1e-9 * (tick % 7)


def engine_step_us(mechanism: Any, sim_step: float, steps: int = REFERENCE_STEPS,
                   repeats: int = 3, every: int = 0) -> tuple[float, float]:
    """
    Return the engine's wall time per step (us) over ``steps`` in one call, and its iterations.

    The best of ``repeats`` calls, and the remainder iterations per step of the last. ``every``
    0: the command held (the stage at rest: one iteration a step); n: the single drive's
    command changes every n steps as ``closed_loop_command`` changes it every tick (one
    kernel command row per step, ``integrator.step``): the motion of the profile's ticks, in one
    call.
    """
    import numpy as np

    from flexure_sim.engine.solver import integrator
    from flexure_sim.engine.solver.simulation import Simulation
    from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL

    sim = Simulation(mechanism, dt=sim_step, relinearize_tol=RELINEARIZE_TOL, energy=False)
    drives = sim.model.drives
    if every and len(drives) == 1:
        sim.set_command(closed_loop_command(0))
    elif drives:
        sim.set_command([0.5 * (d.stroke[0] + d.stroke[1]) for d in drives]
                        if len(drives) > 1 else 0.5 * sum(drives[0].stroke))
    sim.step(100)
    rows = None
    if every and len(drives) == 1:
        rows = np.repeat([drives.kernel_command(np.array([closed_loop_command(k)]))
                          for k in range(-(-steps // every))], every, axis=0)[:steps]
    best = float("inf")
    for _ in range(repeats):
        iterations = sim.stats.iterations
        t0 = time.perf_counter()
        if rows is None:
            sim.step(steps)
        else:
            held = drives.kernel_command(sim.state.command)
            integrator.step(sim.model, sim.data, steps, held, rows)
        best = min(best, time.perf_counter() - t0)
    return 1e6 * best / steps, (sim.stats.iterations - iterations) / steps


def call_costs(mechanism: Any, sim_step: float, steps: int = 10, ticks: int = 500,
               repeats: int = 9) -> dict[str, float]:
    """
    Return the engine's cost per tick (us) called tick by tick and the same steps in one call.

    No node: a ``Simulation`` as the node builds it, ticked by ``engine_steps.advance`` with a
    drive filter (the node's route), against the same steps' commands (one row per step) in one
    call of ``integrator.step`` from the same state; runs of ``ticks`` ticks of ``steps`` steps,
    the two alternating, the best of ``repeats`` each (robust to a shared machine's
    preemptions). ``call_rest``: the command held; ``call_moving``: a closed loop's new command
    every tick (``closed_loop_command``, within a step's slew); ``call_ramp``: the command
    jumping 1 um every tick under a slew rate that makes each tick a ramp over its steps.
    ``*_ratio``: tick by tick over one call (1: no cost per call). Empty unless one drive.
    """
    import numpy as np

    from flexure_sim.engine.solver import integrator
    from flexure_sim.engine.solver.simulation import Simulation
    from flexure_sim.node.inputs.command_checks import CommandFilter, DriveLimits
    from flexure_sim.node.stage.engine_steps import advance
    from flexure_sim.node.stage.stepping_thread import RELINEARIZE_TOL

    out: dict[str, float] = {}
    cases = (("rest", lambda k: 1e-6, 1.0), ("moving", closed_loop_command, 1.0),
             ("ramp", lambda k: 1e-6 * (k % 2), 1e-6 / (steps * sim_step)))
    for name, target, slew in cases:
        sim = Simulation(mechanism, dt=sim_step, relinearize_tol=RELINEARIZE_TOL, energy=False)
        if len(sim.model.drives) != 1:
            return out
        filt = CommandFilter(DriveLimits(-1e-4, 1e-4, slew))
        for k in range(300):
            filt.submit(target(k))
            advance(sim, filt, None, steps, sim_step)
        start, applied = sim.state.copy(), filt.applied
        rows = []  # the same ticks' commands, one per step (the filter's own arithmetic)
        for k in range(ticks):
            filt.submit(target(k))
            filt.begin_tick(steps * sim_step)
            rows += [filt.advance(sim_step) for _ in range(steps)]
        kernel_rows = np.array(rows)[:, None]
        held = sim.model.drives.kernel_command(start.command)
        best = one = float("inf")
        for _ in range(repeats):
            sim.state, filt.target = start.copy(), applied
            filt.hold(applied)
            t0 = time.perf_counter()
            for k in range(ticks):
                filt.submit(target(k))
                advance(sim, filt, None, steps, sim_step)
            best = min(best, time.perf_counter() - t0)
            sim.state = start.copy()
            t0 = time.perf_counter()
            integrator.step(sim.model, sim.data, len(rows), held, kernel_rows)
            one = min(one, time.perf_counter() - t0)
        out[f"call_{name}_us"] = 1e6 * best / ticks
        out[f"call_{name}_one_call_us"] = 1e6 * one / ticks
        out[f"call_{name}_ratio"] = best / one
    return out


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
            ticked = [0]

            def command() -> None:  # a closed loop's new command, a few nm from the last
                if filt is not None and hasattr(filt, "submit_many"):
                    ticked[0] += 1
                    filt.submit_many([closed_loop_command(ticked[0])])

            with loop.publish_calls.hold():  # as the stepping thread publishes
                for _ in range(300):
                    command()
                    loop.tick()
                parts.__init__()
                stats = loop.sim.stats
                steps, iterations = stats.steps, stats.iterations
                for _ in range(ticks):
                    command()
                    loop.tick()
            n = parts.ticks
            for name, total in zip((*TICK_PARTS, "tick"), parts.sums):
                out[f"{name}_us"] = 1e6 * total / n
            out["engine_median_us"] = 1e6 * float(sorted(parts.engine)[n // 2])
            out["iterations_per_step"] = ((stats.iterations - iterations)
                                          / max(1, stats.steps - steps))
            out["steps_per_tick"] = loop.n_steps
            out["topics_per_tick"] = len(loop.interface.tick_topics)
            out.update(_old_routes(loop))
        finally:
            if node is not None:
                node.shutdown()
                node.destroy_node()
            rclpy.try_shutdown(context=context)
            os.chdir(cwd)
    steps = out["steps_per_tick"]
    (out["engine_step_us_reference"],
     out["reference_iterations_per_step"]) = engine_step_us(node.mechanism, sim_step)
    # Like for like: the ticks' own motion (their commands, one row per step) in one call.
    (out["engine_step_us_moving"],
     out["moving_iterations_per_step"]) = engine_step_us(node.mechanism, sim_step,
                                                         every=int(steps))
    out["overhead_factor"] = out["tick_us"] / (steps * out["engine_step_us_reference"])
    out["engine_ratio"] = out["engine_us"] / (steps * out["engine_step_us_reference"])
    out["engine_ratio_moving"] = out["engine_us"] / (steps * out["engine_step_us_moving"])
    out["engine_median_ratio_moving"] = (out["engine_median_us"]
                                         / (steps * out["engine_step_us_moving"]))
    out["tick_budget_us"] = 1e6 / rate
    out.update(call_costs(node.mechanism, sim_step, int(steps)))
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
