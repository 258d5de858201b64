"""The glTF 2.0 JSON objects baker reads and writes, as dataclasses (glTF 2.0 §5, "Properties
Reference"): one class per object kind, one field per property, named as in the JSON.

A field's type says what JSON value it holds (``document.document`` checks each value against
it, and ``document.data`` turns the objects back into JSON). Defaults are the spec's where it
gives one (``byteOffset`` 0, ``normalized`` false, a sampler's REPEAT wrapping, ...), so that the
readers need not repeat them; a property the spec requires has the default None, which the
file's checks (``container``, ``references``) and readers turn into an error that names it.
Keys an object does not define are dropped when it is read: glTF puts what it does not define in
``extensions`` and ``extras``, which are kept as they are.

The field names and defaults are pygltflib's (baker read files with it until it was replaced,
for the 0.1 s its import took from every command), so code and tests written against its
objects read these alike.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional

TRIANGLES = 4  # a primitive's default mode (glTF §5.24.2)
REPEAT = 10497  # a sampler's default wrapping (glTF §5.26)


@dataclass
class Property:
    """What every glTF object may carry: extension objects and application data."""
    extensions: Optional[Dict[str, Any]] = field(default_factory=dict)
    extras: Optional[Any] = field(default_factory=dict)


@dataclass
class Asset(Property):
    generator: Optional[str] = None
    copyright: Optional[str] = None
    version: str = "2.0"
    minVersion: Optional[str] = None


class Attributes:
    """A primitive's attributes: semantic name → accessor index. The eight common ones are
    always attributes (None when absent); any other name the file gives (TEXCOORD_2, _CUSTOM,
    ...) is one too. Not a dataclass: its set of fields is the file's."""

    def __init__(self, POSITION=None, NORMAL=None, TANGENT=None, TEXCOORD_0=None,
                 TEXCOORD_1=None, COLOR_0=None, JOINTS_0=None, WEIGHTS_0=None, **others):
        self.POSITION = POSITION
        self.NORMAL = NORMAL
        self.TANGENT = TANGENT
        self.TEXCOORD_0 = TEXCOORD_0
        self.TEXCOORD_1 = TEXCOORD_1
        self.COLOR_0 = COLOR_0
        self.JOINTS_0 = JOINTS_0
        self.WEIGHTS_0 = WEIGHTS_0
        self.__dict__.update(others)

    def __eq__(self, other) -> bool:
        return type(other) is Attributes and self.__dict__ == other.__dict__

    def __repr__(self) -> str:
        return "Attributes(" + ", ".join(f"{k}={v}" for k, v in self.__dict__.items()) + ")"


@dataclass
class Primitive(Property):
    attributes: Attributes = field(default_factory=Attributes)
    indices: Optional[int] = None
    mode: Optional[int] = TRIANGLES
    material: Optional[int] = None
    targets: Optional[List[Attributes]] = field(default_factory=list)


@dataclass
class Mesh(Property):
    primitives: List[Primitive] = field(default_factory=list)
    weights: Optional[List[float]] = field(default_factory=list)
    name: Optional[str] = None


@dataclass
class AccessorSparseIndices(Property):
    bufferView: int = None
    byteOffset: Optional[int] = 0
    componentType: int = None


@dataclass
class AccessorSparseValues(Property):
    bufferView: int = None
    byteOffset: Optional[int] = 0


@dataclass
class Sparse(Property):
    count: int = None
    indices: AccessorSparseIndices = None
    values: AccessorSparseValues = None


@dataclass
class Accessor(Property):
    bufferView: Optional[int] = None
    byteOffset: Optional[int] = 0
    componentType: int = None
    normalized: Optional[bool] = False
    count: int = None
    type: str = None
    sparse: Optional[Sparse] = None
    max: Optional[List[float]] = field(default_factory=list)
    min: Optional[List[float]] = field(default_factory=list)
    name: Optional[str] = None


@dataclass
class BufferView(Property):
    buffer: int = None
    byteOffset: Optional[int] = 0
    byteLength: int = None
    byteStride: Optional[int] = None
    target: Optional[int] = None
    name: Optional[str] = None


@dataclass
class Buffer(Property):
    uri: Optional[str] = None
    byteLength: int = None
    name: Optional[str] = None


@dataclass
class Perspective(Property):
    aspectRatio: Optional[float] = None
    yfov: float = None
    zfar: Optional[float] = None
    znear: float = None


@dataclass
class Orthographic(Property):
    xmag: float = None
    ymag: float = None
    zfar: float = None
    znear: float = None


@dataclass
class Camera(Property):
    perspective: Optional[Perspective] = None
    orthographic: Optional[Orthographic] = None
    type: str = None
    name: Optional[str] = None


@dataclass
class TextureInfo(Property):
    index: int = None
    texCoord: Optional[int] = 0


@dataclass
class OcclusionTextureInfo(Property):
    index: Optional[int] = None
    texCoord: Optional[int] = None
    strength: Optional[float] = 1.0


@dataclass
class NormalMaterialTexture(Property):
    index: Optional[int] = None
    texCoord: Optional[int] = None
    scale: Optional[float] = 1.0


@dataclass
class PbrMetallicRoughness(Property):
    baseColorFactor: Optional[List[float]] = field(default_factory=lambda: [1.0, 1.0, 1.0, 1.0])
    metallicFactor: Optional[float] = 1.0
    roughnessFactor: Optional[float] = 1.0
    baseColorTexture: Optional[TextureInfo] = None
    metallicRoughnessTexture: Optional[TextureInfo] = None


@dataclass
class Material(Property):
    pbrMetallicRoughness: Optional[PbrMetallicRoughness] = None
    normalTexture: Optional[NormalMaterialTexture] = None
    occlusionTexture: Optional[OcclusionTextureInfo] = None
    emissiveFactor: Optional[List[float]] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    emissiveTexture: Optional[TextureInfo] = None
    alphaMode: Optional[str] = "OPAQUE"
    alphaCutoff: Optional[float] = None
    doubleSided: Optional[bool] = False
    name: Optional[str] = None


@dataclass
class Sampler(Property):
    magFilter: Optional[int] = None
    minFilter: Optional[int] = None
    wrapS: Optional[int] = REPEAT
    wrapT: Optional[int] = REPEAT
    name: Optional[str] = None


@dataclass
class Node(Property):
    mesh: Optional[int] = None
    skin: Optional[int] = None
    rotation: Optional[List[float]] = None
    translation: Optional[List[float]] = None
    scale: Optional[List[float]] = None
    children: Optional[List[int]] = field(default_factory=list)
    matrix: Optional[List[float]] = None
    camera: Optional[int] = None
    weights: Optional[List[float]] = None
    name: Optional[str] = None


@dataclass
class Skin(Property):
    inverseBindMatrices: Optional[int] = None
    skeleton: Optional[int] = None
    joints: Optional[List[int]] = field(default_factory=list)
    name: Optional[str] = None


@dataclass
class Scene(Property):
    name: Optional[str] = None
    nodes: Optional[List[int]] = field(default_factory=list)


@dataclass
class Texture(Property):
    sampler: Optional[int] = None
    source: Optional[int] = None
    name: Optional[str] = None


@dataclass
class Image(Property):
    uri: str = None
    mimeType: str = None
    bufferView: int = None
    name: Optional[str] = None


@dataclass
class AnimationChannelTarget(Property):
    node: Optional[int] = None
    path: str = None


@dataclass
class AnimationSampler(Property):
    input: int = None
    interpolation: Optional[str] = "LINEAR"
    output: int = None


@dataclass
class AnimationChannel(Property):
    sampler: int = None
    target: AnimationChannelTarget = None


@dataclass
class Animation(Property):
    name: Optional[str] = None
    channels: List[AnimationChannel] = field(default_factory=list)
    samplers: List[AnimationSampler] = field(default_factory=list)


@dataclass
class GLTF2(Property):
    """The document: its top-level arrays, and, off the JSON, the GLB binary chunk
    (``binary_blob``) and where the file was read from (``_path``: its folder, ``_name``)."""
    accessors: List[Accessor] = field(default_factory=list)
    animations: List[Animation] = field(default_factory=list)
    asset: Asset = field(default_factory=Asset)
    bufferViews: List[BufferView] = field(default_factory=list)
    buffers: List[Buffer] = field(default_factory=list)
    cameras: List[Camera] = field(default_factory=list)
    extensionsUsed: List[str] = field(default_factory=list)
    extensionsRequired: List[str] = field(default_factory=list)
    images: List[Image] = field(default_factory=list)
    materials: List[Material] = field(default_factory=list)
    meshes: List[Mesh] = field(default_factory=list)
    nodes: List[Node] = field(default_factory=list)
    samplers: List[Sampler] = field(default_factory=list)
    scene: int = None
    scenes: List[Scene] = field(default_factory=list)
    skins: List[Skin] = field(default_factory=list)
    textures: List[Texture] = field(default_factory=list)
    _path = Path()  # not fields: set by ``container.read_document``, not part of the JSON
    _name = ""
    _blob = None

    def binary_blob(self) -> bytes | None:
        """The GLB's binary chunk (None: a .gltf file, or a GLB without one)."""
        return self._blob

    def set_binary_blob(self, blob: bytes | None) -> None:
        self._blob = blob
