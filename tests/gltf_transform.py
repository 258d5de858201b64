"""glTF Transform (npm ``@gltf-transform/*``, pinned in ``tests/transform``) for tests: variants
of a scene as exporters write them, made by the tools studios use.

``variant(kind, source, target)`` runs ``node tests/transform/transform.js KIND SOURCE TARGET``
(kind: ``draco``, ``meshopt``, ``quantize``, ``texture-transform``, ``animated`` or
``emissive``: the script's notes say what each does). The packages are installed on first use
with ``npm ci --prefix tests/transform`` (the README's test command installs only the
validator). ``ktx2`` is made here instead: glTF Transform's KTX 2 encoding needs KTX-Software's
``toktx`` program, which no registry ships, so every PNG or JPEG texture is encoded as UASTC
KTX 2 with the ``alktx2`` package (the test extra) and named by ``KHR_texture_basisu``.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from npm_packages import installed

TRANSFORM_DIR = Path(__file__).resolve().parent / "transform"
SCRIPT = TRANSFORM_DIR / "transform.js"
KINDS = ("draco", "meshopt", "quantize", "texture-transform", "ktx2", "animated", "emissive")


def _node() -> str:
    """node, with the pinned packages installed (``npm ci`` once, when they are missing)."""
    node = shutil.which("node")
    if node is None or not installed(TRANSFORM_DIR, [Path("@gltf-transform/functions")]):
        raise RuntimeError("node and npm are not on PATH: install Node.js (v18 or later)")
    return node


def variant(kind: str, source: Path, target: Path) -> Path:
    """Write ``source`` (a .glb) as ``target``, the ``kind`` of variant of it (``KINDS``)."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, not {kind!r}")
    if kind == "ktx2":
        return ktx2(source, target)
    run = subprocess.run([_node(), str(SCRIPT), kind, str(source), str(target)],
                         capture_output=True, text=True, timeout=300, check=False)
    if run.returncode != 0:
        raise RuntimeError(f"gltf-transform {kind} failed on {source}: {run.stderr.strip()}")
    return target


def ktx2(source: Path, target: Path) -> Path:
    """Write the .glb ``source`` as ``target`` with every texture's image encoded as UASTC
    KTX 2 (``alktx2``), appended to the buffer and named by ``KHR_texture_basisu`` alone (the
    core ``source`` dropped, the extension required): a file only a KTX 2 decoder reads."""
    import io

    import alktx2
    import numpy as np
    import pygltflib
    from PIL import Image

    document = pygltflib.GLTF2().load(str(source))
    blob = bytearray(document.binary_blob() or b"")
    encoded: dict[int, int] = {}
    for texture in document.textures or []:
        if texture.source is None:
            continue
        if texture.source not in encoded:
            image = document.images[texture.source]
            view = document.bufferViews[image.bufferView]
            data = bytes(blob[view.byteOffset or 0:(view.byteOffset or 0) + view.byteLength])
            rgba = np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))
            ktx = alktx2.encode_raw_rgba_to_ktx2(rgba.tobytes(), rgba.shape[1], rgba.shape[0],
                                                 False, codec="uastc")
            blob += b"\0" * (-len(blob) % 4)
            document.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob),
                                                             byteLength=len(ktx)))
            blob += ktx
            document.images.append(pygltflib.Image(bufferView=len(document.bufferViews) - 1,
                                                   mimeType="image/ktx2"))
            encoded[texture.source] = len(document.images) - 1
        texture.extensions = {**(texture.extensions or {}),
                              "KHR_texture_basisu": {"source": encoded[texture.source]}}
        texture.source = None
    if encoded:
        for names in ("extensionsUsed", "extensionsRequired"):
            setattr(document, names, sorted(set(getattr(document, names) or [])
                                            | {"KHR_texture_basisu"}))
    blob += b"\0" * (-len(blob) % 4)
    document.buffers[0].byteLength = len(blob)
    document.set_binary_blob(bytes(blob))
    document.save_binary(str(target))
    return target
