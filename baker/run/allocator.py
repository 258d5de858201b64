"""The C allocator told to keep the memory a bake frees, for the arrays that follow.

A bake makes and drops arrays of megabytes stage after stage (a part's ray origins and
directions, its hits, its terms). glibc's malloc gives each block over 128 KiB its own ``mmap``
and hands it back to the system on ``free``; it raises that threshold only after such a block
is freed, one size at a time. So a new process pays a page fault for every 4 KiB of every new
array, again and again: the demo Cornell room at 4 rays (132,781 texels) took 91,870 minor page
faults, 0.37 s of system time on 2 cores, where 26,490 faults and 0.17 s were enough.
``keep_freed_memory`` sets the threshold to glibc's largest (32 MiB: blocks up to it come from
the heap, freed ones are reused) and trims the heap only when ``TRIM`` bytes lie free at its
top. The command line calls it once at its start; a program that calls the API keeps its own
allocator settings (glibc's own adaptive threshold warms up in it after its first bake).
"""

from __future__ import annotations

import ctypes

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt's parameters (glibc's malloc.h)
MMAP_THRESHOLD = 32 << 20
"""Bytes: blocks smaller come from the heap (glibc's upper bound for this setting on 64 bits)."""
TRIM = 512 << 20
"""Bytes free at the heap's top before glibc gives them back: a long ``baker watch`` process
keeps at most this much of its last bake's memory for the next."""


def keep_freed_memory() -> bool:
    """Set glibc's mmap and trim thresholds (``MMAP_THRESHOLD``, ``TRIM``) for this process;
    False, with nothing changed, where the C library is not glibc (macOS, musl, Windows)."""
    try:
        mallopt = ctypes.CDLL(None).mallopt  # the process's own symbols, the C library's among them
    except (OSError, AttributeError, TypeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM))
