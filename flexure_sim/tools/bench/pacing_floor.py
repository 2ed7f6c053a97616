"""
The floor of real-time pacing on this machine: a paced thread that only burns a tick's work.

    python -m flexure_sim.tools.bench.pacing_floor --rate 4000 --work-us 90 --duration 10

A thread paced as the stage node's stepping thread is (``pacing.Pacer``, the node's default
``wake_spin`` and ``stepping_nice``) busy-waits ``work_us`` at every tick: the node's own tick
time, with no simulation, no ROS, no recording, no other thread of its process. The ticks it
misses are the machine's: its scheduler, other processes and, in a virtual machine, the
host taking the CPU away. Whatever the stage node does, it cannot miss fewer ticks of the same
length at that rate on this machine; ``bench --node`` runs it next to each real-time run with
that run's mean tick.
"""
from __future__ import annotations

import argparse
import json
import threading
import time
from typing import Any, Optional, Sequence

from flexure_sim.node.params.table import STEPPING_NICE, WAKE_SPIN_S
from flexure_sim.node.stage.pacing import Pacer, set_thread_nice


def run(rate: float, work_us: float, duration: float, wake_spin: float = WAKE_SPIN_S,
        nice: int = STEPPING_NICE, warmup: float = 2.0) -> dict[str, Any]:
    """Pace ``work_us`` of busy work at ``rate`` Hz for ``warmup`` + ``duration`` s; figures."""
    first = round(warmup * rate)
    ticks = first + round(duration * rate)
    work = work_us * 1e-6
    out: dict[str, Any] = {}

    def paced() -> None:
        granted, refused = set_thread_nice(nice)
        pacer = Pacer(1.0 / rate, spin_s=min(wake_spin, 1.0 / rate))
        clock = time.perf_counter
        pacer.start()
        for k in range(ticks):
            if k == first:
                pacer.reset_stats()
            pacer.wait()
            end = clock() + work
            while clock() < end:
                pass
            pacer.done()
        stats = pacer.stats
        p50, p99 = stats.late_percentiles(0.5, 0.99)
        out.update(rate_hz=rate, work_us=work_us, duration_s=duration, ticks=stats.ticks,
                   missed_ticks=stats.missed,
                   missed_fraction=stats.missed / stats.ticks if stats.ticks else None,
                   max_late_us=1e6 * stats.max_late_s, late_p50_us=1e6 * p50,
                   late_p99_us=1e6 * p99, slips=stats.slips, wake_spin_s=wake_spin,
                   nice=granted, nice_refused=refused)

    thread = threading.Thread(target=paced, name="pacing-floor")
    thread.start()
    thread.join()
    return out


def summary(r: dict[str, Any]) -> str:
    """One line of a floor run's figures."""
    return (f"{r['rate_hz'] / 1e3:g} kHz, {r['work_us']:.0f} us of work a tick: missed "
            f"{r['missed_ticks']} of {r['ticks']} ({100 * (r['missed_fraction'] or 0):.3f} %), "
            f"worst lateness {r['max_late_us'] / 1e3:.2f} ms (p99 {r['late_p99_us']:.0f} us)")


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command line: one floor run, printed (``--json``: as JSON)."""
    parser = argparse.ArgumentParser(prog="python -m flexure_sim.tools.bench.pacing_floor",
                                     description=__doc__.split("\n\n")[0].strip())
    parser.add_argument("--rate", type=float, default=1000.0, help="ticks per second")
    parser.add_argument("--work-us", type=float, default=100.0, help="busy work per tick, us")
    parser.add_argument("--duration", type=float, default=10.0, help="measured seconds")
    parser.add_argument("--warmup", type=float, default=2.0, help="ignored start, s")
    parser.add_argument("--wake-spin", type=float, default=WAKE_SPIN_S,
                        help=f"busy-wait before each tick, s (the node's wake_spin, default "
                             f"{WAKE_SPIN_S:g})")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    if not (args.rate > 0 and args.work_us >= 0 and args.duration > 0 and args.warmup >= 0
            and args.wake_spin >= 0):
        parser.error("--rate and --duration must be > 0, --work-us, --warmup and --wake-spin "
                     ">= 0")
    result = run(args.rate, args.work_us, args.duration, wake_spin=args.wake_spin,
                 warmup=args.warmup)
    print(json.dumps(result) if args.json else summary(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
