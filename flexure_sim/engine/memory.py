"""
What fits in this process's memory: the check behind refusing a request too large to hold.

A sweep of 10^15 designs or a frequency response at 10^8 frequencies is refused before any
work, with the estimate, rather than growing until the kernel kills the process or a
``MemoryError`` ends it with a traceback. ``available_bytes`` is the smaller of the memory
the kernel reports available (``MemAvailable``, /proc/meminfo) and what the address-space
limit (``RLIMIT_AS``, as ``ulimit -v`` sets it) leaves above the process's current size;
``too_large`` compares an estimate with ``USABLE`` of it.
"""
from __future__ import annotations

import os
import resource
from typing import Optional

#: Fraction of the available memory one request may take (the rest: the interpreter, the
#: libraries, and the estimate's own error).
USABLE = 0.8


def _meminfo_available() -> Optional[int]:
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:  # not Linux: physical memory as the bound
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def _address_space_left() -> Optional[int]:
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        with open("/proc/self/statm", encoding="ascii") as f:
            size = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        size = 0
    return max(0, soft - size)


def available_bytes() -> Optional[int]:
    """Return the bytes this process can still allocate (module doc); None if unknown."""
    bounds = [b for b in (_meminfo_available(), _address_space_left()) if b is not None]
    return min(bounds) if bounds else None


def human(n: float) -> str:
    """Return a byte count as a short text: ``4.6 GB``, ``460 PB``."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if n < 1000.0 or unit == "PB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{n:.0f} B"
        n /= 1000.0
    return f"{n:.3g} EB"  # not reached


def too_large(need: float) -> Optional[str]:
    """
    Return why ``need`` bytes do not fit (module doc), or None if they do (or nothing is known).

    The reason reads ``~4.6 GB, more than the 3.1 GB this process can use``.
    """
    have = available_bytes()
    if have is None or need <= USABLE * have:
        return None
    return f"~{human(need)}, more than the {human(USABLE * have)} this process can use"
