"""Keep glibc from returning freed memory to the OS between messages.

Every frame or cloud a service handles is a few MB; by default glibc serves such blocks with fresh
``mmap`` pages and unmaps them on free, so each message pays ~1 page fault per 4 KiB (measured: a
2 MB frame's encode+decode went from 0.2 ms to 2.5 ms). Raising the mmap and trim thresholds lets the
heap reuse the same pages. Called once per process by the service runtime and the benchmarks.
"""

from __future__ import annotations

import ctypes
import ctypes.util

M_TRIM_THRESHOLD = -1
M_TOP_PAD = -2
M_MMAP_THRESHOLD = -3

_done = False


def tune_malloc(mmap_threshold: int = 64 << 20, trim_threshold: int = 256 << 20, top_pad: int = 16 << 20) -> bool:
    """Apply the thresholds once; returns False where glibc's ``mallopt`` is not available."""
    global _done
    if _done:
        return True
    name = ctypes.util.find_library("c")
    if not name:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    ok = all(mallopt(opt, val) == 1 for opt, val in ((M_MMAP_THRESHOLD, mmap_threshold),
                                                      (M_TRIM_THRESHOLD, trim_threshold),
                                                      (M_TOP_PAD, top_pad)))
    _done = ok
    return ok
