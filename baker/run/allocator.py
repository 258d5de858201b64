"""The C allocator told to keep the memory a bake frees, for the arrays that follow.

A bake makes and drops arrays of megabytes stage after stage (a part's ray origins and
directions, its hits, its terms). glibc's malloc gives each block over its mmap threshold its
own ``mmap``, and trims the heap's top whenever twice that lies free: a new process pays a page
fault for every 4 KiB of every new array, again and again. The demo Cornell room at 4 rays
(132,781 texels) took 91,870 minor page faults, 0.37 s of system time on 2 cores, where 26,490
faults and 0.17 s were enough. ``keep_freed_memory`` takes blocks up to ``MMAP_THRESHOLD`` from
the heap, whose freed memory the next arrays reuse, and trims it only past ``TRIM`` free at its
top. The price is holes in the heap: GlassVaseFlowers' peak memory 357 MiB with glibc's own
settings (its faults 349,000), 400 with these (130,000), 385 with an 8 MiB threshold
(117,000), which on a level of a million triangles faults more than glibc's own settings
(206,000 against 170,000; these 155,000, at the same peak). The command line calls it once at
its start; a program that calls the API keeps its own allocator settings.
"""

from __future__ import annotations

import ctypes

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt's parameters (glibc's malloc.h)
MMAP_THRESHOLD = 32 << 20
"""Bytes: blocks up to this size come from the heap (glibc's largest on 64 bits)."""
TRIM = 64 << 20
"""Bytes free at the heap's top before glibc gives them back."""


def keep_freed_memory() -> bool:
    """Set glibc's mmap and trim thresholds (``MMAP_THRESHOLD``, ``TRIM``) for this process;
    False, with nothing changed, where the C library is not glibc (macOS, musl, Windows)."""
    try:
        mallopt = ctypes.CDLL(None).mallopt  # the process's own symbols, the C library's among them
    except (OSError, AttributeError, TypeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM))
