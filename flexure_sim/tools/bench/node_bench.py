"""
``flexure-sim bench --node``: the stage node's figures, from one run (needs ROS 2).

- **The tick in this process** (`tick_profile`): each part of a tick (intake, engine, report,
  pack, record, publish) and the **overhead factor**, the tick's time over its engine steps at
  the engine's own per-step cost measured in the same process: machine-independent.
- **Real time alone at 1, 2 and 4 kHz**, 10 engine steps a tick (the step scaled: 1e-4, 5e-5,
  2.5e-5 s): a machine 2 or 4 times slower runs the 1 kHz stage as this one runs 2 or 4 kHz.
  Missed ticks, lateness, the tick's parts as the node timed them, the overhead factor of the
  node's own mean tick. Nobody subscribes, so the node records its tick topics and publishes
  none; the 1 kHz run is repeated with every tick topic subscribed by another process (the
  measuring one), which the node then publishes.
- **The closed loop at 1, 2 and 4 kHz** (`closed_loop`: ``pi_controller`` in a second process
  answering every measurement), with the stepping thread spinning through the period
  (``wake_spin`` = the period), sleeping with a short spin before each tick (`SHORT_SPIN_S`,
  the default) and with a shorter one (`SLEEP_SPIN_S`): missed ticks and commands applied at
  the next tick. The less the thread spins, the more of the two cores the controller has
  for its answer, and the later a sleeping thread may wake.
- **The floor** at 1, 2 and 4 kHz (`pingpong`): a bare rclpy ping-pong between two processes,
  paced like the node, without simulation or recording.
- **The pacing floor** at 1, 2 and 4 kHz (`pacing_floor`): a thread paced like the stepping
  thread that busy-waits each real-time run's mean tick, without ROS: the ticks of that length
  this machine itself misses.
- Fast mode's real-time factor, and real time next to a 10 kHz command flood (`flood`).
"""
from __future__ import annotations

from typing import Any, Optional

from flexure_sim.node.params.table import WAKE_SPIN_S
from flexure_sim.node.publish.diagnostics import TICK_PARTS

#: Publish rates of the real-time, closed-loop and floor runs (Hz); 10 engine steps a tick.
RATES = (1000.0, 2000.0, 4000.0)
STEPS_PER_TICK = 10
#: The short busy-wait of the sleeping variant (s): sleep, then spin this long before a tick
#: (the node's default).
SHORT_SPIN_S = WAKE_SPIN_S
#: The shorter busy-wait of the third variant (s): the stepping thread sleeps most of even a
#: 4 kHz period.
SLEEP_SPIN_S = 5e-5
#: The closed loop's variants: ``wake_spin`` per variant name (`_spin_params`).
SPIN_VARIANTS = ("period", "short", "sleep")
#: Rate of the drive-command flood next to the 1 kHz real-time run.
FLOOD_HZ = 10000.0
#: Length of each floor run, s (at most the node runs').
FLOOR_S = 15.0


def _spin_params(rate: float, spin: str) -> dict[str, str]:
    """``wake_spin`` of a variant: the whole period, SHORT_SPIN_S or SLEEP_SPIN_S."""
    spins = {"period": 1.0 / rate, "short": SHORT_SPIN_S, "sleep": SLEEP_SPIN_S}
    return {"wake_spin": repr(spins[spin])}


def bench_node(duration: float = 30.0, step_us: Optional[float] = None) -> dict[str, Any]:
    """
    Every node figure (module docstring) from runs of ``duration`` s each.

    ``step_us``: the engine's per-step time (us, no energy integrals) the bench measured in
    this run (``bench_step_cost``), the denominator of the overhead factors; measured here if
    None.
    """
    from flexure_sim.tools.bench import closed_loop, measure, pacing_floor, pingpong
    from flexure_sim.tools.bench.tick_profile import profile

    profiled = profile(1000.0, 1e-4)
    step_us = step_us if step_us is not None else profiled["engine_step_us_reference"]

    def overhead(run: dict[str, Any]) -> float:
        return run["tick_time_mean_us"] / (run["steps_per_tick"] * step_us)

    out: dict[str, Any] = {"step_us": step_us, "profile": profiled}
    fast = measure.run_node("fast", min(duration, 10.0), 1000.0, 1e-4, True, False)
    out["fast_rtf"] = fast["real_time_factor"]
    out["fast"] = fast
    realtime, loops, floor, pacing = {}, {}, {}, {}
    for rate in RATES:
        key = f"{rate / 1e3:g}kHz"
        run = measure.run_node("realtime", duration, rate, 1.0 / (STEPS_PER_TICK * rate), True,
                               False)
        run["overhead_factor"] = overhead(run)
        realtime[key] = run
        pacing[key] = pacing_floor.run(rate, run["tick_time_mean_us"], min(duration, FLOOR_S))
        for spin in SPIN_VARIANTS:
            loop = closed_loop.run(duration, params=_spin_params(rate, spin), rate=rate)
            loop["overhead_factor"] = overhead(loop)
            loops[f"{key}_{spin}_spin"] = loop
        floor[key] = pingpong.run(rate, min(duration, FLOOR_S))
    every = measure.run_node("realtime", duration, 1000.0, 1e-4, True, True)
    every["overhead_factor"] = overhead(every)
    out["realtime_subscribed"] = every
    out["flood"] = measure.run_node("realtime", duration, 1000.0, 1e-4, True, False,
                                    flood_hz=FLOOD_HZ)
    out["realtime"], out["closed_loop"], out["floor"] = realtime, loops, floor
    out["pacing_floor"] = pacing
    one = realtime["1kHz"]
    out["overhead_factor"] = one["overhead_factor"]
    out["tick_parts_us"] = {part: one[f"{part}_time_mean_us"] for part in TICK_PARTS}
    out["tick_parts_us"]["tick"] = one["tick_time_mean_us"]
    out["engine_ratio"] = one["engine_time_mean_us"] / (one["steps_per_tick"] * step_us)
    return out


def _pct(v: Optional[float]) -> str:
    return "n/a" if v is None else f"{100 * v:.3f} %"


def print_node(nd: dict[str, Any]) -> None:
    """Print the node part of the bench's table."""
    from flexure_sim.tools.bench.closed_loop import summary
    from flexure_sim.tools.bench.pacing_floor import summary as pacing_summary
    from flexure_sim.tools.bench.pingpong import summary as floor_summary

    parts = nd["tick_parts_us"]
    print(f"\nstage_node, 10 engine steps a tick, every topic recorded, published to its "
          f"subscribers (none, but where said); engine per step "
          f"{nd['step_us']:.2f} us (this run)")
    print(f"  overhead factor (1 kHz, the node's mean tick / 10 steps): "
          f"{nd['overhead_factor']:.2f}; engine part {nd['engine_ratio']:.2f}x the bench's "
          "per-step cost")
    print("  tick parts (us): " + ", ".join(f"{k} {v:.1f}" for k, v in parts.items()))
    p = nd["profile"]
    print(f"  in-process profile: tick {p['tick_us']:.1f} us, overhead factor "
          f"{p['overhead_factor']:.2f}; the Snapshot route {p['snapshot_route_us']:.1f} us, "
          f"message-by-message packing {p['encode_route_us']:.1f} us")
    print(f"  its engine part (a new command every tick, {p['iterations_per_step']:.2f} "
          f"iterations a step): {p['engine_ratio']:.2f}x the per-step cost at rest "
          f"({p['reference_iterations_per_step']:.2f}); like for like, "
          f"{p['engine_ratio_moving']:.2f}x the ticks' own commands stepped in one call "
          f"({p['engine_step_us_moving']:.2f} us a step; median tick "
          f"{p['engine_median_ratio_moving']:.2f}x)")
    print(f"  fast mode: real-time factor {nd['fast_rtf']:.2f}")
    for key, r in nd["realtime"].items():
        print(f"  real time {key} alone: missed {r['missed_ticks']} of {r['paced_ticks']} "
              f"({_pct(r['missed_fraction'])}), worst lateness {r['max_late_us'] / 1e3:.1f} ms, "
              f"tick {r['tick_time_mean_us']:.0f} us (overhead factor "
              f"{r['overhead_factor']:.2f}), node CPU {r['node_cpu_cores'] or float('nan'):.2f}")
    r = nd.get("realtime_subscribed")
    if r is not None:
        print(f"  real time 1kHz, every topic subscribed by another process: missed "
              f"{_pct(r['missed_fraction'])}, tick {r['tick_time_mean_us']:.0f} us (publish "
              f"{r['publish_time_mean_us']:.1f} us; overhead factor {r['overhead_factor']:.2f})")
    for r in nd.get("pacing_floor", {}).values():
        print("  pacing floor: " + pacing_summary(r))
    for key, r in nd["closed_loop"].items():
        print(f"  {summary(r)} [wake_spin {r['wake_spin_s'] * 1e3:g} ms], node CPU "
              f"{r['node_cpu_cores'] or float('nan'):.2f}")
    for r in nd["floor"].values():
        print("  floor: " + floor_summary(r))
    f = nd["flood"]
    print(f"  real time 1 kHz next to a {f['flood_sent_per_s']:.0f}/s command flood: missed "
          f"{_pct(f['missed_fraction'])}, {f['command_time_mean_us'] or float('nan'):.1f} us "
          f"per command, {f.get('flood_sent')} sent, {f.get('flood_commands_recorded')} "
          f"recorded, {f.get('flood_commands_lost')} lost")
