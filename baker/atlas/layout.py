"""The lightmap atlas: where every baked triangle lies in which lightmap page.

Made by ``unwrap.py`` from each mesh's ``Charts`` (``planar.py``, ``charts.py``), read by the
rasteriser and by the writer, which carries every vertex attribute onto the split vertices
through ``InstanceUV.vertices``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baker.frozen import read_only


@dataclass(frozen=True)
class Charts:
    """One mesh's charts, in its rigid-free frame (``unwrap.frame_positions``), world units:
    no texel density in them, so that a density change only packs them again.

    Vertices are split along chart seams: chart vertex j copies the mesh's vertex
    ``vertices[j]``; ``triangles[t]`` is the mesh's triangle t over the chart vertices, corners
    in the same order. Each chart lies in its own rectangle: ``uv`` (k, 2) from (0, 0) to
    ``sides[chart[j]]``, one world unit a unit (its surface's area kept: ``planar.py``).
    """

    vertices: np.ndarray  # (k,) int64, the mesh vertex of each chart vertex
    triangles: np.ndarray  # (m, 3) int64 into the chart vertices
    uv: np.ndarray  # (k, 2) float64, world units from its chart's corner
    chart: np.ndarray  # (k,) int64, the chart of each vertex
    sides: np.ndarray  # (c, 2) float64, each chart's rectangle, world units

    def __post_init__(self) -> None:
        read_only(self)


@dataclass(frozen=True)
class InstanceUV:
    """The lightmap unwrap of one baked instance.

    xatlas splits vertices along chart seams: new vertex j copies every attribute of the
    primitive's vertex ``vertices[j]``. ``triangles[t]`` is the primitive's triangle t over the new
    vertices, its corners in the order of ``World.triangles``: for a mirrored instance (negative
    determinant) two corners are swapped against the file, and the writer swaps them back. ``uv`` is in glTF UV convention on the triangle's page: u = x / width,
    v = y / height, with (0, 0) the top-left corner of the page image.
    """

    instance: int  # index into Scene.instances
    vertices: np.ndarray  # (k,) int64, original vertex index of each new vertex
    triangles: np.ndarray  # (m, 3) int64 into the new vertices
    uv: np.ndarray  # (k, 2) float64 in [0, 1]
    pages: np.ndarray  # (m,) int64, page of each triangle; -1 where xatlas gave it no area


    def __post_init__(self) -> None:
        read_only(self)  # a hand-off: later stages read it (frozen.py)


@dataclass(frozen=True)
class Atlas:
    """All lightmap pages (each ``width`` × ``height`` texels) and the unwrap of each instance."""

    width: int
    height: int
    page_count: int
    texel_density: float  # texels per world unit along a surface
    padding: int  # texels kept free between charts
    instances: tuple[InstanceUV, ...]
