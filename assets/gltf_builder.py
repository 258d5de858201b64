"""A tiny glTF 2.0 writer for the project's own scenes (demo scenes and test fixtures).

Units are metres; colours are linear RGB(A) floats unless a parameter says otherwise (images are
sRGB-encoded uint8, as glTF stores them). Positions, normals and UVs are written as float32
accessors, triangle indices as UNSIGNED_INT, all in one buffer. Saving the same scene twice gives
the same bytes.

    b = GltfBuilder()
    white = b.material("white", (0.8, 0.8, 0.8))
    floor = b.shape_mesh("floor", quad(4.0, 4.0), material=white)
    b.node("floor", floor)
    b.save("floor.glb")

The shape helpers (``box``, ``box_face``, ``quad``, ``cylinder``, ``uv_sphere``, ``icosphere``,
``rock``, ``lathe``) return
``(positions (n,3) float64, triangles (m,3) int64, normals (n,3) float64, uv0 (n,2) float64)``
with counter-clockwise winding seen from the side the normal points to (glTF front face).
"""

from __future__ import annotations

import copy
import io
import json
import math
import os
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from baker.gltf import document as gltf_document
from baker.gltf import objects
from baker.gltf.container import read_document
from baker.output.write import glb_file

GENERATOR = "baker assets"

_FLOAT = 5126  # accessor componentType (glTF §3.6.2.2)
_UINT = 5125
_ARRAY_BUFFER = 34962  # buffer view targets
_ELEMENT_ARRAY_BUFFER = 34963
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}
_LINEAR, _LINEAR_MIPMAP_LINEAR = 9729, 9987  # sampler filters

Shape = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


class GltfBuilder:
    """Accumulates materials, meshes and nodes and writes them as one glTF 2.0 asset.

    Every ``material``/``mesh``/``node`` call returns the glTF index of what it added. Nodes never
    given as another node's child are the roots of scene 0, in creation order, unless ``roots`` sets
    them explicitly. ``info`` is a free dict for scene functions to describe what they built (node
    names, triangle ranges, ...) to tests; it is not written to the file.
    """

    def __init__(self) -> None:
        self._blob = bytearray()
        self._buffer_views: list[objects.BufferView] = []
        self._accessors: list[objects.Accessor] = []
        self._materials: list[objects.Material] = []
        self._meshes: list[objects.Mesh] = []
        self._nodes: list[objects.Node] = []
        self._images: list[objects.Image] = []
        self._textures: list[objects.Texture] = []
        self._samplers: list[objects.Sampler] = []
        self._extensions_used: set[str] = set()
        self._child_nodes: set[int] = set()
        self._roots: list[int] | None = None
        self._lights: list[dict[str, Any]] = []
        self.info: dict[str, Any] = {}

    # ------------------------------------------------------------------ buffers and accessors

    def _view(self, data: bytes, target: int | None) -> int:
        """Append ``data`` to the buffer (4-byte aligned) as a new bufferView; return its index."""
        self._blob.extend(b"\0" * (-len(self._blob) % 4))
        view = objects.BufferView(buffer=0, byteOffset=len(self._blob), byteLength=len(data))
        if target is not None:
            view.target = target
        self._blob.extend(data)
        self._buffer_views.append(view)
        return len(self._buffer_views) - 1

    def _float_accessor(self, values: np.ndarray, *, bounds: bool = False) -> int:
        """A float32 vertex-attribute accessor for ``values`` (n, k); min/max when ``bounds``."""
        array = np.ascontiguousarray(values, dtype="<f4")
        count, width = array.shape
        accessor = objects.Accessor(
            bufferView=self._view(array.tobytes(), _ARRAY_BUFFER),
            componentType=_FLOAT,
            count=count,
            type=_TYPES[width],
        )
        if bounds and count:
            # min/max as the float32 values really stored, so readers can trust them bit for bit.
            accessor.min = [float(v) for v in array.min(axis=0)]
            accessor.max = [float(v) for v in array.max(axis=0)]
        self._accessors.append(accessor)
        return len(self._accessors) - 1

    def _index_accessor(self, triangles: np.ndarray) -> int:
        flat = np.ascontiguousarray(triangles, dtype="<u4").reshape(-1)
        self._accessors.append(
            objects.Accessor(
                bufferView=self._view(flat.tobytes(), _ELEMENT_ARRAY_BUFFER),
                componentType=_UINT,
                count=int(flat.size),
                type=_TYPES[1],
            )
        )
        return len(self._accessors) - 1

    # ------------------------------------------------------------------ materials

    def _image_texture(self, pixels: np.ndarray, name: str) -> int:
        """Embed ``pixels`` (h, w, 3|4) uint8 sRGB as a PNG; return the texture index."""
        from PIL import Image as PILImage

        pixels = np.asarray(pixels)
        if pixels.dtype != np.uint8 or pixels.ndim != 3 or pixels.shape[2] not in (3, 4):
            raise ValueError(f"base_color_image must be (h, w, 3|4) uint8, got {pixels.dtype} {pixels.shape}")
        png = io.BytesIO()
        PILImage.fromarray(np.ascontiguousarray(pixels), "RGBA" if pixels.shape[2] == 4 else "RGB").save(png, "PNG")
        view = self._view(png.getvalue(), None)
        self._images.append(objects.Image(bufferView=view, mimeType="image/png", name=name))
        if not self._samplers:
            self._samplers.append(
                objects.Sampler(
                    magFilter=_LINEAR,
                    minFilter=_LINEAR_MIPMAP_LINEAR,
                    wrapS=objects.REPEAT,
                    wrapT=objects.REPEAT,
                )
            )
        self._textures.append(objects.Texture(sampler=0, source=len(self._images) - 1, name=name))
        return len(self._textures) - 1

    def material(
        self,
        name: str,
        base_color: Sequence[float] = (0.8, 0.8, 0.8),
        *,
        emissive: Sequence[float] = (0.0, 0.0, 0.0),
        emissive_strength: float | None = None,
        metallic: float = 0.0,
        roughness: float = 1.0,
        double_sided: bool = False,
        alpha_mode: str = "OPAQUE",
        alpha_cutoff: float | None = None,
        base_color_image: np.ndarray | None = None,
        normal_image: np.ndarray | None = None,
        normal_scale: float | None = None,
        extensions: dict[str, Any] | None = None,
    ) -> int:
        """Add a metallic-roughness material; return its index.

        ``base_color``: linear RGB or RGBA factor (alpha 1 if omitted). ``emissive``: linear RGB
        factor in [0, 1]; ``emissive_strength`` multiplies it via KHR_materials_emissive_strength.
        ``base_color_image``: (h, w, 3|4) uint8 sRGB pixels, row 0 at the top (v = 0), sampled from
        TEXCOORD_0 and multiplied by the factor. ``normal_image``: (h, w, 3) uint8 tangent-space
        normals (0.5 + 0.5·n per channel, glTF's +X right, +Y up in the image) as the
        ``normalTexture`` on TEXCOORD_0, with ``normal_scale``. ``extensions``: extra material extensions
        ({"KHR_materials_transmission": {...}, ...}), recorded in extensionsUsed.
        """
        color = [float(c) for c in base_color]
        if len(color) == 3:
            color.append(1.0)
        if len(color) != 4:
            raise ValueError(f"base_color must have 3 or 4 components, got {len(color)}")
        if alpha_mode not in ("OPAQUE", "MASK", "BLEND"):
            raise ValueError(f"alpha_mode must be OPAQUE, MASK or BLEND, got {alpha_mode!r}")
        pbr = objects.PbrMetallicRoughness(
            baseColorFactor=color, metallicFactor=float(metallic), roughnessFactor=float(roughness)
        )
        if base_color_image is not None:
            pbr.baseColorTexture = objects.TextureInfo(index=self._image_texture(base_color_image, name))
        mat = objects.Material(
            name=name,
            pbrMetallicRoughness=pbr,
            emissiveFactor=[float(c) for c in emissive],
            alphaMode=alpha_mode,
            doubleSided=bool(double_sided),
        )
        if alpha_cutoff is not None:
            mat.alphaCutoff = float(alpha_cutoff)
        if normal_image is not None:
            mat.normalTexture = objects.NormalMaterialTexture(
                index=self._image_texture(normal_image, f"{name} normals"),
                scale=None if normal_scale is None else float(normal_scale))
        exts: dict[str, Any] = {}
        if emissive_strength is not None:
            exts["KHR_materials_emissive_strength"] = {"emissiveStrength": float(emissive_strength)}
        exts.update(extensions or {})
        if exts:
            mat.extensions = exts
            self._extensions_used.update(exts)
        self._materials.append(mat)
        return len(self._materials) - 1

    # ------------------------------------------------------------------ meshes and nodes

    def mesh(
        self,
        name: str,
        positions: np.ndarray,
        triangles: np.ndarray,
        *,
        normals: np.ndarray | None = None,
        uv0: np.ndarray | None = None,
        uv1: np.ndarray | None = None,
        colors: np.ndarray | None = None,
        material: int | None = None,
        tangents: np.ndarray | None = None,
    ) -> int:
        """Add a mesh of one triangle primitive; return its index.

        ``positions`` (n, 3) metres, ``triangles`` (m, 3) vertex indices (zero-area triangles are
        kept), ``normals`` (n, 3) unit vectors or None (omitted: readers use flat normals),
        ``uv0``/``uv1`` (n, 2) glTF UV space (v = 0 at the image top), ``colors`` (n, 3|4) linear
        floats written as COLOR_0, ``material`` a material index or None (glTF default material),
        ``tangents`` (n, 4) glTF TANGENT (xyz along +u, w the bitangent's sign) or None.
        """
        positions = np.asarray(positions, dtype=np.float64)
        triangles = np.asarray(triangles)
        if positions.ndim != 2 or positions.shape[1] != 3:
            raise ValueError(f"{name}: positions must be (n, 3), got {positions.shape}")
        n = len(positions)
        if triangles.ndim != 2 or triangles.shape[1] != 3 or not np.issubdtype(triangles.dtype, np.integer):
            raise ValueError(f"{name}: triangles must be (m, 3) integers, got {triangles.dtype} {triangles.shape}")
        if triangles.size and (triangles.min() < 0 or triangles.max() >= n):
            raise ValueError(f"{name}: triangle indices must lie in [0, {n})")
        attributes = objects.Attributes(POSITION=self._float_accessor(positions, bounds=True))
        for key, values, widths in (
            ("NORMAL", normals, (3,)),
            ("TEXCOORD_0", uv0, (2,)),
            ("TEXCOORD_1", uv1, (2,)),
            ("COLOR_0", colors, (3, 4)),
            ("TANGENT", tangents, (4,)),
        ):
            if values is None:
                continue
            values = np.asarray(values, dtype=np.float64)
            if values.ndim != 2 or values.shape[0] != n or values.shape[1] not in widths:
                raise ValueError(f"{name}: {key} must be ({n}, {'|'.join(map(str, widths))}), got {values.shape}")
            setattr(attributes, key, self._float_accessor(values))
        primitive = objects.Primitive(
            attributes=attributes, indices=self._index_accessor(triangles), mode=objects.TRIANGLES
        )
        if material is not None:
            if not 0 <= material < len(self._materials):
                raise ValueError(f"{name}: no material {material}")
            primitive.material = material
        self._meshes.append(objects.Mesh(name=name, primitives=[primitive]))
        return len(self._meshes) - 1

    def shape_mesh(self, name: str, shape: Shape, **kwargs: Any) -> int:
        """``mesh`` for a shape helper's (positions, triangles, normals, uv0); ``kwargs`` as ``mesh``."""
        positions, triangles, normals, uv0 = shape
        return self.mesh(name, positions, triangles, normals=normals, uv0=uv0, **kwargs)

    def node(
        self,
        name: str,
        mesh: int | None = None,
        *,
        translation: Sequence[float] | None = None,
        rotation: Sequence[float] | None = None,
        scale: Sequence[float] | None = None,
        matrix: np.ndarray | None = None,
        children: Sequence[int] = (),
        extensions: dict[str, Any] | None = None,
        extras: dict[str, Any] | None = None,
    ) -> int:
        """Add a node; return its index.

        ``translation`` metres, ``rotation`` unit quaternion (x, y, z, w), ``scale`` per axis;
        or ``matrix``: (4, 4) local-to-parent transform acting on column vectors (stored
        column-major, as glTF wants), exclusive with TRS. ``children`` are earlier node indices;
        they stop being roots. ``extras``: the node's application data (e.g. ``foliage``).
        """
        if matrix is not None and any(v is not None for v in (translation, rotation, scale)):
            raise ValueError(f"{name}: give either matrix or translation/rotation/scale, not both")
        if mesh is not None and not 0 <= mesh < len(self._meshes):
            raise ValueError(f"{name}: no mesh {mesh}")
        node = objects.Node(name=name, mesh=mesh)
        if translation is not None:
            node.translation = [float(v) for v in translation]
        if rotation is not None:
            node.rotation = [float(v) for v in rotation]
        if scale is not None:
            node.scale = [float(v) for v in scale]
        if matrix is not None:
            m = np.asarray(matrix, dtype=np.float64)
            if m.shape != (4, 4):
                raise ValueError(f"{name}: matrix must be (4, 4), got {m.shape}")
            node.matrix = [float(v) for v in m.T.reshape(-1)]
        for child in children:
            if not 0 <= child < len(self._nodes) or child in self._child_nodes:
                raise ValueError(f"{name}: child {child} is not an existing parentless node")
        node.children = [int(c) for c in children]
        self._child_nodes.update(node.children)
        if extensions:
            node.extensions = dict(extensions)
            self._extensions_used.update(extensions)
        if extras:
            node.extras = dict(extras)
        self._nodes.append(node)
        return len(self._nodes) - 1

    def light(
        self,
        kind: str,
        *,
        name: str = "",
        color: Sequence[float] = (1.0, 1.0, 1.0),
        intensity: float = 1.0,
        range: float | None = None,
        inner_cone: float | None = None,
        outer_cone: float | None = None,
        extras: dict[str, Any] | None = None,
    ) -> int:
        """Add a KHR_lights_punctual light definition; return its index in the ``lights`` array.

        ``kind``: "directional" (``intensity`` in lux), "point" or "spot" (candela); ``color``
        linear RGB; ``range`` metres (point/spot); cone angles in radians (spot). Place it with
        ``node(..., extensions={"KHR_lights_punctual": {"light": index}})``: it shines down the
        node's local −Z.
        """
        if kind not in ("directional", "point", "spot"):
            raise ValueError(f"light kind must be directional, point or spot, got {kind!r}")
        light: dict[str, Any] = {"type": kind, "color": [float(c) for c in color],
                                 "intensity": float(intensity)}
        if name:
            light["name"] = name
        if range is not None:
            light["range"] = float(range)
        if kind == "spot":
            spot = {}
            if inner_cone is not None:
                spot["innerConeAngle"] = float(inner_cone)
            if outer_cone is not None:
                spot["outerConeAngle"] = float(outer_cone)
            light["spot"] = spot
        if extras:
            light["extras"] = dict(extras)
        self._lights.append(light)
        self._extensions_used.add("KHR_lights_punctual")
        return len(self._lights) - 1

    def roots(self, nodes: Sequence[int]) -> None:
        """Set the root nodes of scene 0 explicitly (default: every node that is nobody's child)."""
        self._roots = [int(n) for n in nodes]

    # ------------------------------------------------------------------ output

    def document(self, bin_uri: str | None = None) -> objects.GLTF2:
        """The asset as a document of glTF objects; its single buffer has ``bin_uri`` (None: GLB chunk).

        The buffer's bytes are ``self.binary()``; the document is built afresh on every call.
        """
        roots = self._roots if self._roots is not None else [
            i for i in range(len(self._nodes)) if i not in self._child_nodes
        ]
        doc = objects.GLTF2(
            asset=objects.Asset(version="2.0", generator=GENERATOR),
            scene=0,
            scenes=[objects.Scene(nodes=roots)],
            nodes=_copy(self._nodes),
            meshes=_copy(self._meshes),
            materials=_copy(self._materials),
            accessors=_copy(self._accessors),
            bufferViews=_copy(self._buffer_views),
            buffers=[objects.Buffer(byteLength=len(self.binary()), uri=bin_uri)] if self._blob else [],
            images=_copy(self._images),
            textures=_copy(self._textures),
            samplers=_copy(self._samplers),
            extensionsUsed=sorted(self._extensions_used),
        )
        if self._lights:
            doc.extensions = {"KHR_lights_punctual": {"lights": copy.deepcopy(self._lights)}}
        return doc

    def json_data(self, bin_uri: str | None = None) -> dict:
        """The asset's glTF JSON data (``document`` written as JSON gives the file's text)."""
        return gltf_document.data(self.document(bin_uri))

    def binary(self) -> bytes:
        """The buffer's bytes, padded to a multiple of 4."""
        return bytes(self._blob) + b"\0" * (-len(self._blob) % 4)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the asset to ``path``: ``.glb`` (binary) or ``.gltf`` (JSON + ``<stem>.bin``).

        Files are written atomically (temporary file, then rename). Returns the path.
        """
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix == ".glb":
            _write_atomic(path, self.glb_bytes())
        elif suffix == ".gltf":
            bin_name = path.stem + ".bin"
            data = self.json_data(bin_uri=bin_name if self._blob else None)
            text = json.dumps(data, indent=2) + "\n"
            if self._blob:
                _write_atomic(path.with_name(bin_name), self.binary())
            _write_atomic(path, text.encode("utf-8"))
        else:
            raise ValueError(f"{path}: extension must be .glb or .gltf")
        return path

    def glb_bytes(self) -> bytes:
        """The asset as GLB bytes (header, JSON chunk padded with spaces, BIN chunk)."""
        return glb_file(self.json_data(), self.binary())


def edited_glb(source: Path, edit: Callable[[objects.GLTF2], None], target: Path) -> Path:
    """The .glb ``source`` with ``edit`` applied to its document (read by baker), written as
    the .glb ``target``; returns ``target``."""
    document = read_document(source)
    edit(document)
    _write_atomic(Path(target), glb_file(gltf_document.data(document), document.binary_blob()))
    return Path(target)


def _copy(items: list[Any]) -> list[Any]:
    return copy.deepcopy(items)


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, then rename it over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


# ---------------------------------------------------------------------- transforms


def quat_axis_angle(axis: Sequence[float], degrees: float) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) rotating by ``degrees`` about ``axis`` (right-handed)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    half = math.radians(degrees) / 2.0
    s = math.sin(half)
    return (float(a[0] * s), float(a[1] * s), float(a[2] * s), float(math.cos(half)))


def rotation_matrix(axis: Sequence[float], degrees: float) -> np.ndarray:
    """(3, 3) rotation about ``axis`` by ``degrees`` (right-handed), acting on column vectors."""
    x, y, z, w = quat_axis_angle(axis, degrees)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def transformed(
    shape: Shape, *, rotation: np.ndarray | None = None, translation: Sequence[float] = (0, 0, 0)
) -> Shape:
    """A shape with its positions rotated (by the (3, 3) ``rotation``) then translated; normals rotated."""
    positions, triangles, normals, uv = shape
    r = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
    return positions @ r.T + np.asarray(translation, dtype=np.float64), triangles, normals @ r.T, uv


def merged(*shapes: Shape) -> Shape:
    """Several shapes as one (triangle indices offset)."""
    offsets = np.cumsum([0] + [len(s[0]) for s in shapes[:-1]])
    return (
        np.concatenate([s[0] for s in shapes]),
        np.concatenate([s[1] + o for s, o in zip(shapes, offsets)]),
        np.concatenate([s[2] for s in shapes]),
        np.concatenate([s[3] for s in shapes]),
    )


# ---------------------------------------------------------------------- shapes

# Face name -> (normal axis, sign); the tangent pair (u, v) of each face satisfies u x v = normal.
_FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


def box_face(size: Sequence[float] = (1.0, 1.0, 1.0), face: str = "+y", inward: bool = False) -> Shape:
    """One face of a box centred at the origin: 4 vertices, 2 triangles.

    ``face`` names the side ("+x", "-x", "+y", "-y", "+z", "-z"); its normal points away from the
    centre, or towards it when ``inward`` (the face of a room seen from inside). UVs span [0, 1]².
    """
    if face not in _FACES:
        raise ValueError(f"face must be one of {_FACES}, got {face!r}")
    half = np.asarray(size, dtype=np.float64) / 2.0
    axis = "xyz".index(face[1])
    sign = 1.0 if face[0] == "+" else -1.0
    normal = np.zeros(3)
    normal[axis] = sign
    u = np.zeros(3)
    u[(axis + 1) % 3] = 1.0
    v = np.cross(normal, u)  # u x v = normal
    centre = normal * half
    hu, hv = half[(axis + 1) % 3], half[(axis + 2) % 3]
    corners = np.array([(-1, -1), (1, -1), (1, 1), (-1, 1)], dtype=np.float64)
    positions = centre + corners[:, :1] * hu * u + corners[:, 1:] * hv * v
    triangles = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], dtype=np.float64)
    if inward:
        normal = -normal
        triangles = triangles[:, ::-1].copy()
    return positions, triangles, np.tile(normal, (4, 1)), uv


def box(size: Sequence[float] = (1.0, 1.0, 1.0), inward: bool = False, faces: Sequence[str] = _FACES) -> Shape:
    """An axis-aligned box centred at the origin, 4 vertices and 2 triangles per face (24 / 12).

    ``size`` (sx, sy, sz) metres. ``inward``: faces and normals point to the centre (a room seen
    from inside). ``faces`` keeps only the named sides (e.g. leave out "+z" for an open front).
    """
    return merged(*(box_face(size, f, inward) for f in faces))


def quad(width: float = 1.0, depth: float = 1.0) -> Shape:
    """A ``width`` (x) by ``depth`` (z) rectangle on the XZ plane, centred, normal +Y, 2 triangles."""
    return box_face((width, 0.0, depth), "+y")


def lathe(profile: np.ndarray, segments: int = 32, normals2d: np.ndarray | None = None) -> Shape:
    """A surface of revolution about +Y; smooth normals, open ends.

    ``profile`` (k, 2) of (radius, y) points ordered bottom to top; the outside of the surface is
    to the right of the profile walked in that order (+radius for a vertical wall). ``normals2d``
    (k, 2) overrides the (radial, y) normals otherwise averaged from the profile's segments.
    Triangles whose three vertices coincide on the axis (radius 0) are left out.
    """
    profile = np.asarray(profile, dtype=np.float64)
    k = len(profile)
    if normals2d is None:
        d = np.diff(profile, axis=0)
        seg_n = np.stack([d[:, 1], -d[:, 0]], axis=1)
        seg_n /= np.linalg.norm(seg_n, axis=1, keepdims=True)
        normals2d = np.zeros((k, 2))
        normals2d[:-1] += seg_n
        normals2d[1:] += seg_n
    normals2d = np.asarray(normals2d, dtype=np.float64)
    normals2d = normals2d / np.linalg.norm(normals2d, axis=1, keepdims=True)
    theta = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    cos, sin = np.cos(theta), np.sin(theta)
    cos[-1], sin[-1] = 1.0, 0.0  # the seam column repeats the first exactly
    r, y = profile[:, :1], profile[:, 1:]
    positions = np.stack([r * cos, np.broadcast_to(y, (k, segments + 1)), r * sin], axis=-1).reshape(-1, 3)
    nr, ny = normals2d[:, :1], normals2d[:, 1:]
    normals = np.stack([nr * cos, np.broadcast_to(ny, (k, segments + 1)), nr * sin], axis=-1).reshape(-1, 3)
    uu, vv = np.meshgrid(np.linspace(0.0, 1.0, segments + 1), 1.0 - np.linspace(0.0, 1.0, k))
    uv = np.stack([uu, vv], axis=-1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(k - 1), np.arange(segments), indexing="ij")
    a = (i * (segments + 1) + j).reshape(-1)
    b, c, d = a + segments + 1, a + 1, a + segments + 2  # b above a, c beside a, d above c
    lower = np.stack([a, b, c], axis=1)
    upper = np.stack([b, d, c], axis=1)
    on_axis = profile[:, 0] == 0.0
    row = i.reshape(-1)
    keep_lower = ~on_axis[row]  # a and c both on the axis: degenerate
    keep_upper = ~on_axis[row + 1]  # b and d both on the axis: degenerate
    triangles = np.concatenate([lower[keep_lower], upper[keep_upper]]).astype(np.int64)
    return positions, triangles, normals, uv


def _disc(radius: float, y: float, segments: int, up: bool) -> Shape:
    theta = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(theta), np.full(segments, y), radius * np.sin(theta)], axis=1)
    positions = np.concatenate([[[0.0, y, 0.0]], ring])
    j = np.arange(segments)
    nxt = (j + 1) % segments
    centre = np.zeros(segments, np.int64)
    triangles = np.stack([centre, nxt + 1, j + 1] if up else [centre, j + 1, nxt + 1], axis=1)
    normals = np.tile([0.0, 1.0 if up else -1.0, 0.0], (segments + 1, 1))
    uv = 0.5 + 0.5 * positions[:, [0, 2]] / radius
    return positions, triangles.astype(np.int64), normals, uv


def cylinder(radius: float = 0.5, height: float = 1.0, segments: int = 32, caps: bool = True) -> Shape:
    """A closed cylinder about +Y centred at the origin (y in [-height/2, height/2]).

    Smooth normals on the side, flat normals on the caps (separate vertices). Outward.
    """
    h = height / 2.0
    side = lathe(np.array([[radius, -h], [radius, h]]), segments)
    if not caps:
        return side
    return merged(side, _disc(radius, -h, segments, up=False), _disc(radius, h, segments, up=True))


def uv_sphere(radius: float = 0.5, rings: int = 16, segments: int = 32) -> Shape:
    """A sphere centred at the origin: ``rings`` latitude bands, ``segments`` longitudes; smooth normals, outward."""
    phi = np.linspace(np.pi, 0.0, rings + 1)  # bottom pole to top pole
    n2 = np.stack([np.sin(phi), np.cos(phi)], axis=1)
    n2[0], n2[-1] = (0.0, -1.0), (0.0, 1.0)
    profile = radius * n2
    return lathe(profile, segments, normals2d=n2)


def icosphere(radius: float = 0.5, subdivisions: int = 1) -> Shape:
    """A geodesic sphere centred at the origin: an icosahedron whose triangles are cut in four
    ``subdivisions`` times (20·4^s faces: 80 for s = 1), vertices pushed onto the sphere,
    shared between faces, with the true sphere's (smooth) normals; UVs from the direction's
    longitude and latitude (a placeholder: baker unwraps its own)."""
    t = (1.0 + 5.0 ** 0.5) / 2.0
    corners = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
               (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    points = [np.array(c, np.float64) / np.linalg.norm(c) for c in corners]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        middle: dict[tuple[int, int], int] = {}

        def midpoint(a: int, b: int) -> int:
            key = (min(a, b), max(a, b))
            if key not in middle:
                m = points[a] + points[b]
                points.append(m / np.linalg.norm(m))
                middle[key] = len(points) - 1
            return middle[key]

        faces = [tri for a, b, c in faces
                 for ab, bc, ca in [(midpoint(a, b), midpoint(b, c), midpoint(c, a))]
                 for tri in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))]
    normals = np.array(points)
    uv = np.stack([0.5 + np.arctan2(normals[:, 2], normals[:, 0]) / (2 * np.pi),
                   0.5 - np.arcsin(np.clip(normals[:, 1], -1, 1)) / np.pi], axis=1)
    return radius * normals, np.array(faces, np.int64), normals, uv


def rock(radius: float = 1.0, subdivisions: int = 4, seed: int = 0) -> Shape:
    """A crumpled rock: an ``icosphere`` whose radius forty random waves crumple (2–60 per
    radian, the shorter the lower: relief of about 0.15 ``radius``), normals averaged from its
    faces: projected charts fold over at its relief (at 5,120 faces it is so crumpled that
    baker leaves it to xatlas; from 20,480 the folded charts are split). 20·4^s faces;
    deterministic in ``seed``."""
    points, triangles, _, uv = icosphere(1.0, subdivisions)
    rng = np.random.default_rng(seed)
    scale = np.ones(len(points))
    for _ in range(40):
        way = rng.normal(size=3)
        frequency = rng.uniform(2.0, 60.0)
        scale += 0.3 / frequency ** 0.8 * np.sin(
            frequency * points @ (way / np.linalg.norm(way)) + rng.uniform(0.0, 2 * np.pi))
    positions = radius * points * scale[:, None]
    face = np.cross(positions[triangles[:, 1]] - positions[triangles[:, 0]],
                    positions[triangles[:, 2]] - positions[triangles[:, 0]])
    normals = np.zeros_like(positions)
    for corner in range(3):
        np.add.at(normals, triangles[:, corner], face)
    return positions, triangles, normals / np.linalg.norm(normals, axis=1, keepdims=True), uv
