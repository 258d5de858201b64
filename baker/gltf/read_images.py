"""The images the materials' base colour and emissive textures use, decoded (``read_images``,
``decode_image``); every other image file checked to be there (``check_images``); the
``Scene.images`` entries (``scene_images``) and an image's pixels after the load
(``image_pixels``)."""

from __future__ import annotations

import dataclasses
import os
from typing import Any

import numpy as np

from baker.gltf import budget, images, objects
from baker.gltf.accessors import buffer_view
from baker.gltf.buffers import decode_data_uri
from baker.gltf.context import Context, invalid, referred
from baker.gltf.files import read_descriptor
from baker.gltf.references import texture_slots
from baker.gltf.scene import Image, Scene


def read_images(ctx: Context, spent: budget.Budget) -> None:
    """Read every image's bytes (a file once: kept in ``ctx.image_files`` for the writer,
    counted in the input's budget ``spent``) and its header (``images.header``: a format its
    textures allow, pixels its bytes can hold), then check the pixels of all of them together
    (``budget.check_pixels``), before any is decoded."""
    allowed, users = _image_formats(ctx.document), _image_users(ctx.document)
    for i in range(len(ctx.document.images)):
        with referred(users.get(i, f"images[{i}]")):
            _read_image(ctx, i, allowed[i], spent)
    budget.check_pixels([(f"images[{i}]", head.pixels) for i, head in ctx.headers.items()],
                        ctx.file)


def _read_image(ctx: Context, i: int, allowed: tuple[str, ...], spent: budget.Budget) -> None:
    """Read ``images[i]``'s file (when it is one) and header (``read_images``)."""
    image, where = ctx.document.images[i], f"images[{i}]"
    if _is_file(image.uri):
        descriptor, size = ctx.folder.open(image.uri, f"{where}.uri")
        try:
            spent.spend(size, f'the image file "{image.uri}"', f"{where}.uri")
            ctx.image_files[i] = read_descriptor(descriptor, size, image.uri, ctx.file,
                                                 f"{where}.uri")
        finally:
            os.close(descriptor)
    data, label = _image_data(ctx, i)
    ctx.headers[i] = images.header(data, allowed, label, ctx.file, where)


def _image_users(document: objects.GLTF2) -> dict[int, str]:
    """The first material texture slot that uses each image (its JSON path, e.g.
    ``materials[0].pbrMetallicRoughness.baseColorTexture``), to name in messages."""
    users: dict[int, str] = {}
    textures = document.textures or []
    for m, material in enumerate(document.materials or []):
        for at, index in texture_slots(dataclasses.asdict(material), f"materials[{m}]"):
            if not isinstance(index, int) or not 0 <= index < len(textures):
                continue
            texture = textures[index]
            sources = [texture.source] + [value.get("source") for value in
                                          (texture.extensions or {}).values()
                                          if isinstance(value, dict)]
            for source in sources:
                if isinstance(source, int):
                    users.setdefault(source, at)
    return users


def _is_file(uri: Any) -> bool:
    """Whether an image's ``uri`` names a file (not a data URI, not absent)."""
    return uri is not None and not (isinstance(uri, str) and uri.startswith("data:"))


def _image_formats(document: objects.GLTF2) -> list[tuple[str, ...]]:
    """The formats each image may have: those every texture naming it allows
    (``images.FORMATS``: PNG or JPEG as a core source, WebP through ``EXT_texture_webp``, …;
    none through an extension baker does not know), any format baker reads when none does."""
    allowed: list[set[str] | None] = [None] * len(document.images or [])

    def name(index: Any, formats: tuple[str, ...]) -> None:
        if isinstance(index, int) and not isinstance(index, bool) and 0 <= index < len(allowed):
            allowed[index] = set(formats) if allowed[index] is None else allowed[index] & set(formats)

    for texture in document.textures or []:
        name(texture.source, images.FORMATS[None])
        for extension, value in (texture.extensions or {}).items():
            if isinstance(value, dict):
                name(value.get("source"), images.FORMATS.get(extension, ()))
    return [images.ANY_FORMAT if formats is None
            else tuple(f for f in images.ANY_FORMAT if f in formats) for formats in allowed]


def _image_data(ctx: Context, index: int) -> tuple[bytes, str]:
    """The encoded bytes of ``images[index]`` and a label naming it in messages: its file's
    (read by ``read_images``), its bufferView's or its data URI's."""
    image = ctx.document.images[index]
    where = f"images[{index}]"
    if index in ctx.image_files:
        return ctx.image_files[index], f'"{image.uri}"'
    if image.bufferView is not None:
        view, _ = buffer_view(ctx.document, ctx.buffers, image.bufferView, ctx.file,
                              f"{where}.bufferView")
        return bytes(view), f"the image in bufferViews[{image.bufferView}]"
    if image.uri is None:
        raise invalid("image has neither uri nor bufferView", ctx.file, where)
    return decode_data_uri(image.uri, ctx.file, where), "the embedded image"


def decode_image(ctx: Context, index: int, keep: bool = True) -> np.ndarray | None:
    """Decode ``images[index]`` (its header read by ``read_images``) once: into (h, w, 4) uint8
    RGBA, row 0 at the top (sRGB as stored), kept in ``ctx.decoded`` when ``keep``; else
    decoded only to check it."""
    if index in ctx.decoded:
        return ctx.decoded[index]
    data, label = _image_data(ctx, index)
    head, where = ctx.headers[index], f"images[{index}]"
    if keep:
        budget.check_sampled(sum(p.shape[0] * p.shape[1] for p in ctx.decoded.values()),
                             head.pixels, f"{head.width}×{head.height}", label, ctx.file, where)
    pixels = images.decode(data, head, label, ctx.file, where, keep)
    if keep:
        ctx.decoded[index] = pixels
    return pixels


def image_pixels(scene: Scene, index: int) -> np.ndarray:
    """``scene.images[index]`` as (h, w, 4) uint8 RGBA, decoded again from the bytes the load
    read (its file's, its bufferView's or its data URI's): for an image the bake does not
    sample (``baker preview`` reads the lightmap pages of a baked file)."""
    ctx = Context(scene.document, list(scene.buffers), str(scene.path), None)
    ctx.image_files = {i: image.data for i, image in enumerate(scene.images)
                       if image.data is not None}
    data, label = _image_data(ctx, index)
    where = f"images[{index}]"
    head = images.header(data, images.ANY_FORMAT, label, ctx.file, where)
    return images.decode(data, head, label, ctx.file, where)


def check_images(ctx: Context) -> None:
    """Decode every image the bake does not sample (normal, occlusion, metallic-roughness
    maps, unused images), only to check it: every image an output carries was decoded once.
    One this installation cannot decode (KTX 2 without opengl-basisu) is checked from its
    header alone, and recorded in ``ctx.skipped``."""
    users = _image_users(ctx.document)
    for i in range(len(ctx.document.images)):
        if i in ctx.decoded:
            continue
        try:
            with referred(users.get(i, f"images[{i}]")):
                decode_image(ctx, i, keep=False)
        except images.Undecodable as exc:
            ctx.skip(f"images[{i}]", f"checked from its header only: {exc.message} ({exc.fix})")


def scene_images(ctx: Context) -> tuple[Image, ...]:
    """One Image per glTF image: decoded when a texture the bake samples uses it, else a 1×1
    white placeholder; with its file's bytes when it is a file."""
    out = []
    for i, image in enumerate(ctx.document.images):
        pixels = ctx.decoded.get(i)
        if pixels is None:
            pixels = np.full((1, 1, 4), 255, np.uint8)
        uri = image.uri if image.uri and not image.uri.startswith("data:") else ""
        out.append(Image(pixels=pixels, name=image.name or uri, data=ctx.image_files.get(i)))
    return tuple(out)
