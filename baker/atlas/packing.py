"""Charts' rectangles packed into lightmap pages, a skyline at a time.

Every chart lies in its own rectangle of whole texels (``planar.py``, ``charts.py``), so
packing is placing rectangles: tallest first (their longer side), each where its top comes
lowest over the skyline of the page (the bottom-left rule), as it is or turned a quarter, the
first of equals; a rectangle that fits no open page opens the next. Rectangles are kept
``2 · padding`` texels apart; they may touch the page's sides (the lightmaps' sampler clamps to
the edge, ``output/write.py``). One page is sized to its
charts: as wide as a square of their texels would be (at most ``page`` a side), as tall as they
come; several pages are ``page`` a side. A pure function of its input, in a fraction of a
second for 100,000 charts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baker.jit import jit

_SQUARE = 1.1  # a single page is first tried this much wider than the square of its texels


@dataclass(frozen=True)
class Packed:
    """Where each rectangle went: ``page`` (n,) int64, ``corner`` (n, 2) int64 its texels'
    top-left corner on the page, ``turned`` (n,) bool a quarter turn (its sides swapped);
    every page ``width`` × ``height`` texels, ``pages`` of them."""

    page: np.ndarray
    corner: np.ndarray
    turned: np.ndarray
    width: int
    height: int
    pages: int


def pack(cells: np.ndarray, padding: int, page: int) -> Packed:
    """Pack rectangles of ``cells`` (n, 2) int64 texels (each at most ``page`` a side) into
    pages of at most ``page`` texels a side (see the module)."""
    cells = np.asarray(cells, np.int64)
    if not len(cells):
        return Packed(np.zeros(0, np.int64), np.zeros((0, 2), np.int64), np.zeros(0, bool),
                      0, 0, 0)
    gap = 2 * int(padding)
    grown = cells + gap  # each with the gap to its neighbours; the page grown by as much
    order = np.lexsort((np.arange(len(cells)), -grown.min(axis=1), -grown.max(axis=1)))
    square = int(np.ceil(np.sqrt(_SQUARE * float((grown[:, 0] * grown[:, 1]).sum()))))
    widest = int(cells.min(axis=1).max())
    for width in dict.fromkeys((min(max(square, widest), page), page)):
        page_of, corner, turned = _skyline(grown[order], width + gap, page + gap, 1)
        if page_of.max() == 0:
            break
    else:
        page_of, corner, turned = _skyline(grown[order], page + gap, page + gap, len(cells))
    out_page = np.empty_like(page_of)
    out_corner = np.empty_like(corner)
    out_turned = np.empty_like(turned)
    out_page[order], out_corner[order], out_turned[order] = page_of, corner, turned
    pages = int(page_of.max()) + 1
    if pages > 1:
        return Packed(out_page, out_corner, out_turned, page, page, pages)
    ends = out_corner + np.where(out_turned[:, None], cells[:, ::-1], cells)
    width, height = (int(e) for e in ends.max(axis=0))
    return Packed(out_page, out_corner, out_turned, width, height, 1)


@jit
def _skyline(cells, width, height, most_pages):
    """Place ``cells`` (n, 2), in order, on pages of ``width`` × ``height``, each on the first
    page where it fits, at the place its top is lowest (then leftmost) over that page's
    skyline, turned or not; at most ``most_pages`` (a cell that fits none gets page
    ``most_pages``). Returns page (n,), corner (n, 2), turned (n,) and, in ``corner``'s
    place for the unplaced, zeros."""
    n = len(cells)
    page_of = np.full(n, most_pages, np.int64)
    corner = np.zeros((n, 2), np.int64)
    turned = np.zeros(n, np.bool_)
    xs = np.empty(n + 2, np.int64)
    ys = np.empty(n + 2, np.int64)
    left = n
    for p in range(most_pages):
        if left == 0:
            break
        xs[0], ys[0] = 0, 0
        segments = 1
        for i in range(n):
            if page_of[i] != most_pages:
                continue
            best_top, best_x, best_s, best_turn = height + 1, 0, -1, False
            for turn in range(2):
                w, h = (cells[i, 0], cells[i, 1]) if turn == 0 else (cells[i, 1], cells[i, 0])
                if turn == 1 and w == h:
                    break
                for s in range(segments):
                    x = xs[s]
                    if x + w > width:
                        break
                    y = 0
                    t = s
                    while t < segments and xs[t] < x + w:
                        y = max(y, ys[t])
                        t += 1
                    if y + h < best_top or (y + h == best_top and x < best_x):
                        best_top, best_x, best_s, best_turn = y + h, x, s, turn == 1
            if best_s < 0 or best_top > height:
                continue
            w, h = (cells[i, 1], cells[i, 0]) if best_turn else (cells[i, 0], cells[i, 1])
            page_of[i] = p
            corner[i, 0], corner[i, 1] = best_x, best_top - h
            turned[i] = best_turn
            segments = _raised(xs, ys, segments, best_s, best_x + w, best_top, width)
            left -= 1
    return page_of, corner, turned


@jit
def _raised(xs, ys, segments, s, end, top, width):
    """The skyline (``xs``, ``ys``: each segment's start and height, ``segments`` of them)
    with [xs[s], end) raised to ``top``; equal neighbours joined. Returns the new count."""
    start = xs[s]
    t = s  # the first segment that reaches past ``end``
    while t + 1 < segments and xs[t + 1] <= end:
        t += 1
    rest_y = ys[t]
    tail = end < width and (t + 1 >= segments or xs[t + 1] > end)
    # new layout: [..s-1], (start, top), (end, rest_y) if tail, [t+1..]
    keep = segments - (t + 1)
    shift = s + 1 + (1 if tail else 0) - (t + 1)
    if shift > 0:
        for j in range(segments - 1, t, -1):
            xs[j + shift], ys[j + shift] = xs[j], ys[j]
    elif shift < 0:
        for j in range(t + 1, segments):
            xs[j + shift], ys[j + shift] = xs[j], ys[j]
    xs[s], ys[s] = start, top
    if tail:
        xs[s + 1], ys[s + 1] = end, rest_y
    segments = s + 1 + (1 if tail else 0) + keep
    out = 0  # join neighbours of equal height
    for j in range(segments):
        if out > 0 and ys[out - 1] == ys[j]:
            continue
        xs[out], ys[out] = xs[j], ys[j]
        out += 1
    return out
