"""Reading a glTF 2.0 file into a ``Scene``: the first stage of the pipeline.

Why a stage of its own: every later stage wants plain arrays — triangles in a mesh's local space,
float64 world matrices per placement, materials reduced to what light transport needs — and none
of them should know about buffers, strides, sparse accessors or node hierarchies. ``load`` and
the modules of its steps are the only code that decodes glTF binary data. It keeps the file's
document (``objects``) so that the writer adds the bake to it and leaves everything else as it was.

In order, ``load`` does (each step a module of ``baker.gltf``, sharing ``context.Context``):
1. read the file (``.gltf`` JSON or ``.glb``, told apart by the magic bytes, not the suffix) and
   check ``asset.version`` and ``extensionsRequired`` (``container``, ``extensions``);
2. walk the scene's node tree into float64 world matrices (``read_nodes``) and check the
   accessors the meshes use against the input's budget (``instances``);
3. resolve every buffer to bytes (GLB binary chunk, data URI, or a file beside the ``.gltf``,
   ``buffers``), and decode Draco and meshopt compressed geometry into plain accessors
   (``decompress``);
4. decode the images the materials' base colour and emissive textures use (``read_images``),
   read the materials, then the default material glTF prescribes (appended last,
   ``read_materials``); check that every other image file is there, so that nothing the output
   carries is found missing after the bake;
5. read the meshes the nodes use (``read_meshes``, their numbers through ``accessors``) and make
   one ``Instance`` per (node, primitive), or per GPU instance of it (``instances``); then the
   lights (``read_lights``).

Choices worth knowing:
- ``Scene.images`` has one entry per glTF image, so indices match the file. Only images that a
  material's base colour or emissive texture uses are decoded; every other entry (normal maps,
  metallic-roughness, occlusion, unused) is a 1×1 white placeholder, since the bake never samples
  them.
- TEXCOORD sets are kept from TEXCOORD_0 up to the first missing one: ``TextureRef.texcoord``
  indexes ``Primitive.texcoords`` directly, so sets after a gap (TEXCOORD_1 without TEXCOORD_0)
  cannot be stored; they are listed in ``Scene.skipped``.
- Primitives are read only for meshes that the scene's nodes use, in mesh order, one
  ``Primitive`` per mesh primitive however many nodes place it. Instances follow the node tree
  depth first, children in file order.
- Strips and fans are expanded with the glTF spec's vertex order (glTF 2.0 §3.7.2.1), so the
  winding is preserved; degenerate triangles are kept. Trailing indices of a TRIANGLES primitive
  that do not make a whole triangle are dropped.
- Node rotations are normalised quaternions; scale, negative or non-uniform, is kept exactly.
- Every problem with the file is an ``InputError`` naming the file, the glTF JSON path and a fix.
"""

from __future__ import annotations

from pathlib import Path

from baker.gltf import budget
from baker.gltf.buffers import check_buffer_budget, resolve_buffers
from baker.gltf.container import read_document
from baker.gltf.context import Context
from baker.gltf.decompress import compressed, decompressed
from baker.gltf.files import SceneFolder
from baker.gltf.instances import check_declared_sizes, instantiate
from baker.gltf.materials import MIRROR_ROUGHNESS, classify, no_lightmap_reason
from baker.gltf.read_images import check_images, read_images, scene_images
from baker.gltf.read_lights import read_lights
from baker.gltf.read_materials import read_materials
from baker.gltf.read_nodes import walk_nodes
from baker.gltf.scene import Scene


def load(path: str | Path, mirror_roughness: float = MIRROR_ROUGHNESS,
         animated: str = "bake", hard_links: bool = False, contained: bool = False) -> Scene:
    """Read a ``.gltf`` or ``.glb`` file into a ``Scene`` (see ``baker.gltf.scene``).

    Geometry stays in each mesh's local space (glTF units, metres); ``Instance.world`` is the
    (4, 4) float64 local-to-world matrix. Raises ``InputError`` for anything in the file that
    baker cannot read, naming the file, the glTF JSON path and what to do. ``mirror_roughness``:
    metals smoother than this are mirrors (``materials.classify``), which get no lightmap.
    ``animated``: what becomes of node-animated instances (an animation drives the transform
    of their node or of an ancestor): "bake" them in their rest pose with a warning, keep them
    as "occlude"rs only (rest pose, no texels), or "skip" them (no instance at all: neither
    baked nor casting shadows); each is listed with its reason in ``Scene.skipped``.
    ``hard_links``: read files the URIs name that have other names too (``files.SceneFolder``).
    ``contained``: the scene file itself is opened as the files it names are (inside its
    folder, no link out, one name): for files as untrusted as their contents (``baker hook``).

    Every file is opened once, relative to the scene's folder, and the whole input is checked
    against ``gltf.budget`` before anything is allocated for it: the nodes, the buffers'
    declared bytes, the accessors the meshes use, then every image's header.
    """
    path = Path(path)
    with SceneFolder(path.parent, str(path), hard_links) as folder:
        spent = budget.Budget(str(path))
        document = read_document(path, folder if contained else None, contained=contained,
                                 spent=spent)
        ctx = Context(document, [], str(path), folder)
        placements = walk_nodes(ctx)
        check_declared_sizes(ctx, placements)
        check_buffer_budget(document, str(path), spent)
        ctx.buffers = resolve_buffers(document, folder)
        if compressed(document):
            ctx.document, ctx.buffers = decompressed(document, ctx.buffers, str(path))
        read_images(ctx, spent)
        materials = read_materials(ctx)
        check_images(ctx)
        images = scene_images(ctx)
        unbaked = [no_lightmap_reason(classify(m, images, mirror_roughness)) for m in materials]
        primitives, instances = instantiate(ctx, placements, materials, unbaked, animated,
                                            spent.spent)
        lights = read_lights(ctx, placements)
    return Scene(
        path=path,
        document=ctx.document,
        primitives=tuple(primitives),
        instances=tuple(instances),
        materials=tuple(materials),
        images=images,
        skipped=tuple(ctx.skipped),
        lights=lights,
        mirror_roughness=float(mirror_roughness),
        buffers=tuple(ctx.buffers),
        inputs=dict(folder.opened),
    )
