"""How much of the machine other processes took while a benchmark timed something.

The 2 cores are shared with other processes (other sessions, each its own scheduler autogroup).
Linux shares the CPU fairly between autogroups, not threads: while another session keeps a
core busy, a 2-thread run of ours gets about the one core a 1-thread run gets, and its
"speed-up" measures the neighbours, not our code (issue 12: the 32-member FlyingNapkin batch
measured 0.95-1.05x with the others at 1.3 cores, 1.99x with them at 0.02). So every timing
is labelled with the others' use, in cores: the machine's busy time (``/proc/stat``: user,
nice, system, irq, softirq, steal) less this process's CPU time, over the wall time. The
machine's busy time comes in 10 ms ticks per core, so the label is good to about 0.02 s over
the wall time (+-0.4 cores for a 50 ms timing, +-0.01 for 2 s): time long enough to trust it.
"""

from __future__ import annotations

import time
from pathlib import Path

#: Others' use (cores) below which a timed pair counts as quiet.
QUIET_CORES = 0.15

_TICK = 0.01  # /proc/stat counts USER_HZ = 100 ticks per second


def _machine_busy() -> float | None:
    """Busy CPU seconds of the whole machine since boot (None where /proc is unavailable)."""
    try:
        f = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError, IndexError):
        return None
    user, nice, system, _idle, _iowait, irq, softirq, steal = f[:8]
    return (user + nice + system + irq + softirq + steal) * _TICK


def timed(fn) -> tuple[float, float]:
    """Calls ``fn``; returns (wall seconds, cores the other processes used meanwhile; NaN
    where unknown)."""
    busy0, cpu0, t0 = _machine_busy(), time.process_time(), time.perf_counter()
    fn()
    wall, cpu, busy1 = time.perf_counter() - t0, time.process_time() - cpu0, _machine_busy()
    if busy0 is None or busy1 is None or wall <= 0:
        return wall, float("nan")
    return wall, max(busy1 - busy0 - cpu, 0.0) / wall
