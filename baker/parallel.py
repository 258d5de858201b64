"""Running chunks of work on every core.

Embree and the numba kernels release the GIL, so a thread pool keeps both cores busy; each chunk
writes only its own rows of preallocated outputs, so the result is the same bytes for any chunk
size, thread count or order.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, TypeVar

Chunk = TypeVar("Chunk")


def cores() -> int:
    """Cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def run_chunks(work: Callable[[Chunk], None], chunks: Iterable[Chunk], threads: int = 0) -> None:
    """Call ``work`` on every chunk, on ``threads`` threads (0: one per core; 1: in this one)."""
    chunks = list(chunks)
    threads = threads or cores()
    if threads == 1 or len(chunks) < 2:
        for chunk in chunks:
            work(chunk)
    else:
        with ThreadPoolExecutor(min(threads, len(chunks))) as pool:
            list(pool.map(work, chunks))
