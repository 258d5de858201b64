"""Running chunks of work on every core.

Embree and the numba kernels release the GIL, so a thread pool keeps both cores busy; each chunk
writes only its own rows of preallocated outputs, so the result is the same bytes for any chunk
size, thread count or order.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from typing import Callable, Iterable, TypeVar

from baker.run.interruptible import check_interrupted

Chunk = TypeVar("Chunk")

CHUNK_RAYS = 1 << 18  # rays per work unit at most: 4096 texels × 64 rays


def texels_per_chunk(chunk_texels: int, rays: int) -> int:
    """Texels per work unit when each texel casts ``rays``: at most ``chunk_texels`` and at most
    ``CHUNK_RAYS`` rays. Bounds a chunk's memory (about 150 bytes per ray) and its time, which is
    how long a worker thread runs on after Ctrl-C (a thread cannot be stopped inside a chunk)."""
    return max(1, min(chunk_texels, CHUNK_RAYS // max(rays, 1)))


def even_slices(count: int, step: int, least: int = 1) -> list[slice]:
    """Consecutive slices covering ``range(count)``: of at most ``step`` rows, at least
    ``least`` of them (when there are rows enough), all of about the same size, so that
    threads given a few chunks end together (no small last one to idle on); none for none."""
    chunks = min(max(-(-count // step), least), count) if count else 0
    bounds = [count * k // chunks for k in range(chunks + 1)] if chunks else [0]
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]


def cores() -> int:
    """Cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def run_chunks(work: Callable[[Chunk], None], chunks: Iterable[Chunk], threads: int = 0) -> None:
    """Call ``work`` on every chunk, on ``threads`` threads (0: one per core; 1: in this one).

    When a chunk raises, or this thread is interrupted (Ctrl-C raises KeyboardInterrupt here while
    it waits), the chunks not yet started are cancelled: the error comes out once the chunks
    already running end, about one chunk's time, not after the whole queue.
    """
    chunks = list(chunks)
    threads = threads or cores()
    if threads == 1 or len(chunks) < 2:
        for chunk in chunks:
            check_interrupted()
            work(chunk)
        return
    failed = threading.Event()

    def guarded(chunk: Chunk) -> None:
        """``work(chunk)``, skipped once any chunk has failed, or an interrupt has come
        (``run.interruptible``): a worker thread takes the next chunk from the queue the
        instant its own ends, before this thread wakes to cancel it."""
        if failed.is_set():
            return
        try:
            check_interrupted()
        except BaseException:
            failed.set()
            raise
        try:
            work(chunk)
        except BaseException:
            failed.set()
            raise

    pool = ThreadPoolExecutor(min(threads, len(chunks)))
    try:
        futures = [pool.submit(guarded, chunk) for chunk in chunks]
        done, _ = wait(futures, return_when=FIRST_EXCEPTION)
        check_interrupted()
        for future in futures:  # re-raise the first error, in chunk order
            if future in done:
                future.result()
    finally:
        failed.set()  # also on Ctrl-C while waiting: no chunk starts from here on
        pool.shutdown(wait=True, cancel_futures=True)
