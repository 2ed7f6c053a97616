"""
A CPU wake-up latency request (Linux PM QoS), held while real-time stepping runs.

Writing a latency limit in microseconds (a 32-bit integer) to ``/dev/cpu_dma_latency`` and
keeping the file open asks the kernel's cpuidle governor to put idle CPUs only into idle
states that they leave within that limit; closing the file (or the process ending) withdraws
the request, and reading the file gives the limit in effect for the whole machine (Linux
Documentation/admin-guide/pm/cpuidle.rst, "Power Management Quality of Service for CPUs";
cyclictest holds the same request while it measures). A limit of 0 selects the polling idle
state: an idle CPU spins in the kernel instead of halting, and a thread woken on it runs at
once.

Why the node can ask for it (``cpu_latency_us``, off by default): on a virtual machine a
halted virtual CPU has to be woken by the host before a thread can run on it, and that
sometimes takes milliseconds. It hits every
thread that sleeps between ticks: the stepping thread after a sleep, the recorder, a
controller in another process waiting for the next measurement. Measured on this project's
2-core VM (a paced Python loop of 250 us of work per 1 ms tick, sleeping all but the last
50 us; load ~1.5 from other jobs): wake-up lateness p99 531 us and 44 of 5000 ticks missed
without the request, 25 us and 4 of 5000 with it. The node at its default ``wake_spin``
never sleeps at 1 kHz, and there the request made no consistent difference (BENCHMARKS.md).
The price: idle CPUs poll instead of resting (power, and host CPU time on a VM).
"""
from __future__ import annotations

import errno
import struct
from typing import BinaryIO, Optional

#: The PM QoS device of the CPU latency limit.
DEVICE = "/dev/cpu_dma_latency"
#: The request's format: a native 32-bit signed integer, microseconds.
_VALUE = struct.Struct("=i")


class CpuLatencyRequest:
    """An open request: in effect until `release` (or the process ends)."""

    def __init__(self, handle: BinaryIO, latency_us: int) -> None:
        self._handle: Optional[BinaryIO] = handle
        self.latency_us = latency_us

    @property
    def held(self) -> bool:
        return self._handle is not None

    def release(self) -> None:
        """Withdraw the request (closing the file does it); idempotent."""
        handle, self._handle = self._handle, None
        if handle is not None:
            handle.close()


def request_cpu_latency(latency_us: int, device: str = DEVICE
                        ) -> tuple[Optional[CpuLatencyRequest], str]:
    """
    Ask for CPU wake-ups within ``latency_us`` (>= 0) for as long as the result is held.

    Returns the request and "" when granted, or None and why not (one line that says how to
    allow it) when the kernel refused it or has no such device.
    """
    try:
        handle = open(device, "wb", buffering=0)  # noqa: SIM115 - held open on purpose
    except FileNotFoundError:
        return None, (f"cpu_latency_us {latency_us} not requested: {device} does not exist "
                      "(a Linux kernel with PM QoS has it)")
    except PermissionError as exc:
        return None, (
            f"cpu_latency_us {latency_us} refused ({exc.strerror}: {device}); idle CPUs may "
            "halt, and a thread woken on one (on a virtual machine: up to milliseconds) starts "
            f"late. Allow it with write access to {device}, e.g. a udev rule "
            "'KERNEL==\"cpu_dma_latency\", GROUP=\"<your group>\", MODE=\"0660\"'")
    try:
        handle.write(_VALUE.pack(int(latency_us)))
    except OSError as exc:
        handle.close()
        reason = errno.errorcode.get(exc.errno or 0, str(exc.errno))
        return None, f"cpu_latency_us {latency_us} refused by the kernel ({reason}: {exc})"
    return CpuLatencyRequest(handle, int(latency_us)), ""


def latency_in_effect(device: str = DEVICE) -> Optional[int]:
    """Return the CPU latency limit in effect (us; the smallest request held), or None."""
    try:
        with open(device, "rb") as f:
            return _VALUE.unpack(f.read(_VALUE.size))[0]
    except OSError:
        return None
