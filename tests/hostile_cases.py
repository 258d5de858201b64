"""A generator of hostile inputs and faults, by family, each with the outcome baker owes it.

Every case starts from the same ``Layout`` — a small ``.gltf`` + ``.bin`` scene in ``scene/``, a
previous bake in ``out/``, and beside them decoys an attacker would aim at (a secret, copies of
the scene's buffer and texture with the secret appended, so that a scene which reached them
would bake) — edits it as an attacker would, and says what baker must do (``Plan``): the
command, its exit code, what its message says, which folder is the output's place, and
optionally a signal to send and when. ``tests/test_hostile_generated.py`` runs each and checks,
besides the plan, what holds for every case: nothing outside the output's place changed, a
refused or interrupted bake left the previous output as it was, the secret is in no file
written, and the process stayed under the time and memory ceilings.

The families (``FAMILIES``): origins (where a URI may lead), formats (what an image may be),
budgets (what an input may declare), state (what a bake state may say), hook (what a
repository may hold), faults (signals, outputs that are no files). ``cases(long=False)`` is the
fast set the default suite runs; ``cases(long=True)`` several hundred.
"""

from __future__ import annotations

import functools
import io
import json
import os
import secrets
import signal
import socket
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from PIL import Image as PILImage

from assets.gltf_builder import GltfBuilder, quad
from assets.make_scenes import checker
from baker.cli.common import OUTPUTS_CHANGED

FAST = ["--rays", "2", "--page-size", "32", "--quiet"]
PREVIOUS = b"the previous bake: must survive every failure\n"
FAMILIES = ("origins", "formats", "budgets", "state", "hook", "faults")


class Layout:
    """A scene folder beside decoys: ``root/secret.txt``, ``root/secret.bin`` (the scene's
    buffer + the secret), ``root/secret.png`` (its texture + the secret), ``root/scene/`` with
    ``scene.gltf``, ``scene.bin``, ``tex.png``, and ``root/out/`` holding a previous bake.
    ``json`` is the scene's glTF, edited, then written by ``save``."""

    def __init__(self, root: Path):
        self.root, self.folder, self.out = root, root / "scene", root / "out"
        self.folder.mkdir()
        self.out.mkdir()
        self.secret = f"BAKER-DECOY-{secrets.token_hex(8)}".encode()
        builder = GltfBuilder()
        material = builder.material("floor", (0.8, 0.8, 0.8))
        builder.node("floor", builder.shape_mesh("floor", quad(2.0, 2.0), material=material))
        self.gltf = builder.save(self.folder / "scene.gltf")
        self.json = json.loads(self.gltf.read_text())
        self.bin = self.folder / self.json["buffers"][0]["uri"]
        self.png = self.folder / "tex.png"
        PILImage.fromarray(checker(8, 2)).save(self.png)
        (root / "secret.txt").write_bytes(self.secret)
        (root / "secret.bin").write_bytes(self.bin.read_bytes() + self.secret)
        (root / "secret.png").write_bytes(self.png.read_bytes() + self.secret)
        self.output = self.out / "baked.glb"
        self.output.write_bytes(PREVIOUS)

    def with_texture(self, uri: str, slot: str = "baseColorTexture",
                     extension: str | None = None) -> None:
        """Give the floor's material a texture whose image has ``uri`` (``slot``: which;
        ``extension``: the texture extension naming it, None for the core ``source``)."""
        self.json["images"] = [{"uri": uri}]
        self.json["textures"] = [{"source": 0} if extension is None
                                 else {"extensions": {extension: {"source": 0}}}]
        if extension is not None:
            self.json["extensionsUsed"] = [extension]
        material = self.json["materials"][0]
        if slot == "baseColorTexture":
            material.setdefault("pbrMetallicRoughness", {})[slot] = {"index": 0}
        else:
            material[slot] = {"index": 0}

    def textures(self, names: list[str], extension: str | None = None) -> None:
        """One material, primitive and colour texture for each image file of ``names``."""
        self.json["images"] = [{"uri": name} for name in names]
        self.json["textures"] = [{"source": k} if extension is None
                                 else {"extensions": {extension: {"source": k}}}
                                 for k in range(len(names))]
        if extension is not None:
            self.json["extensionsUsed"] = [extension]
        base = self.json["materials"][0]
        self.json["materials"] = [json.loads(json.dumps(base)) for _ in names]
        for k, material in enumerate(self.json["materials"]):
            material.setdefault("pbrMetallicRoughness", {})["baseColorTexture"] = {"index": k}
        primitive = self.json["meshes"][0]["primitives"][0]
        self.json["meshes"][0]["primitives"] = [dict(primitive, material=k)
                                                for k in range(len(names))]

    def save(self) -> Path:
        self.gltf.write_text(json.dumps(self.json))
        return self.gltf

    def bake(self, *args: str, output: Path | None = None) -> list[str]:
        """The saved scene's ``baker bake`` arguments (2 rays, 32-texel pages)."""
        self.save()
        return ["bake", str(self.gltf), "-o", str(output or self.output), *FAST, *args]


@dataclass
class Plan:
    """What a case runs and what baker owes it. ``argv``: the ``baker`` command; ``before``:
    commands run first (a previous bake whose state the case edits, through ``edit``);
    ``code``: the exit codes allowed; ``says``: what its stderr (or stdout) holds; ``place``:
    the output's place (``out/`` unless given), the only folder where files may change;
    ``signal``/``after``: a signal sent so many seconds in; ``reader``: a FIFO a thread reads
    (its bytes checked to be ``streams``' start)."""

    argv: list[str]
    code: tuple[int, ...]
    says: tuple[str, ...] = ()
    place: Path | None = None
    before: list[list[str]] = field(default_factory=list)
    edit: Callable[[], None] | None = None
    signal: int | None = None
    after: float = 0.0
    reader: Path | None = None
    streams: bytes = b""


@dataclass(frozen=True)
class Case:
    """One generated case: its family, a name, and ``make(layout) → Plan``."""

    family: str
    name: str
    make: Callable[[Layout], Plan]
    fast: bool = False

    @property
    def id(self) -> str:
        return f"{self.family}:{self.name}"


# ------------------------------------------------------------------------------------------------
# origins: every way a URI may try to lead out of the scene's folder


def spellings(root: Path, name: str) -> dict[str, str]:
    """URIs of the decoy ``root/name`` (outside the scene's folder ``root/scene``), by the
    name of the spelling: ``..``, percent-encoded once and twice, absolute, a scheme, UNC,
    backslashes, NUL."""
    absolute = (root / name).as_posix()
    return {"dotdot": "../" + name, "encoded slash": "..%2F" + name,
            "encoded dots": "%2E%2E/" + name, "lowercase": "%2e%2e%2f" + name,
            "absolute": absolute, "double slash": "/" + absolute,
            "file scheme": "file://" + absolute, "http scheme": "http://localhost/" + name,
            "down and up": "sub/../../" + name, "many up": "../" * 12 + absolute.lstrip("/"),
            "encoded down and up": "sub%2F..%2F..%2F" + name,
            "double encoded": "%252e%252e/" + name, "backslashes": "..\\" + name,
            "unc": "\\\\localhost\\share\\" + name, "nul": "sub/%00/../../" + name,
            "encoded absolute": "%2F" + absolute.lstrip("/"), "dot segments": "./sub/./../../" + name}


TEXTURE_SLOTS = {"colour": "baseColorTexture", "normal": "normalTexture",
                 "occlusion": "occlusionTexture", "emissive": "emissiveTexture"}
"""The material slots an image may fill: sampled by the bake (colour, emissive) or only carried
to the output (normal, occlusion)."""
_SLOTS = {"buffer": ("buffers[0].uri", "secret.bin")} | {
    slot: ("images[0].uri", "secret.png") for slot in TEXTURE_SLOTS}


def _point(layout: Layout, slot: str, uri: str) -> None:
    """Point the scene's buffer, or an image in a texture slot, at ``uri``."""
    if slot == "buffer":
        layout.json["buffers"][0]["uri"] = uri
    else:
        layout.with_texture(uri, TEXTURE_SLOTS[slot])


def _spelling(slot: str, spelling: str) -> Callable[[Layout], Plan]:
    def make(layout: Layout) -> Plan:
        (layout.folder / "sub").mkdir()
        where, decoy = _SLOTS[slot]
        _point(layout, slot, spellings(layout.root, decoy)[spelling])
        return Plan(layout.bake(), (1,), (where,))
    return make


def _linked(slot: str, link: str) -> Callable[[Layout], Plan]:
    """A symbolic link, hard link or special file in the folder, named by ``slot``."""
    def make(layout: Layout) -> Plan:
        where, decoy = _SLOTS[slot]
        name = "linked" + (".bin" if slot == "buffer" else ".png")
        path, code, says = layout.folder / name, (1,), (where,)
        if link == "symlink out":
            path.symlink_to(layout.root / decoy)
            says += ("leads out of the scene's folder",)
        elif link == "folder link out":
            (layout.folder / "up").symlink_to(layout.root, target_is_directory=True)
            name, says = f"up/{decoy}", says + ("leads out of the scene's folder",)
        elif link == "relative link out":
            path.symlink_to(f"../{decoy}")
            says += ("leads out of the scene's folder",)
        elif link == "link to /dev/zero":
            path.symlink_to("/dev/zero")
            says += ("leads out of the scene's folder",)
        elif link == "link loop":
            path.symlink_to("other" + path.suffix)
            (layout.folder / ("other" + path.suffix)).symlink_to(name)
            says += ("symbolic links",)
        elif link == "link inside":
            real = layout.bin if slot == "buffer" else layout.png
            path.symlink_to(real.name)
            code, says = (0,), ()
        elif link == "absolute link inside":
            path.symlink_to(layout.bin if slot == "buffer" else layout.png)
            code, says = (0,), ()
        elif link == "hard link":
            os.link(layout.root / decoy, path)
            says += ("2 names", "--allow-hard-links")
        elif link == "hard link allowed":  # to a copy outside without the secret: read
            real = layout.bin if slot == "buffer" else layout.png
            copy = layout.root / ("copy" + real.suffix)
            copy.write_bytes(real.read_bytes())
            os.link(copy, path)
            code, says = (0,), ()
        elif link == "fifo":
            os.mkfifo(path)
            says += ("a FIFO",)
        elif link == "socket":
            server = socket.socket(socket.AF_UNIX)
            server.bind(str(path))
            server.close()
            says += ("unreadable",)
        elif link == "folder":
            path.mkdir()
            says += ("a folder",)
        _point(layout, slot, name)
        args = ("--allow-hard-links",) if link == "hard link allowed" else ()
        return Plan(layout.bake(*args), code, says)
    return make


LINKS = ("symlink out", "folder link out", "relative link out", "link to /dev/zero", "link loop",
         "link inside", "absolute link inside", "hard link", "hard link allowed", "fifo",
         "socket", "folder")


def _origins() -> list[Case]:
    fast_spellings = {("buffer", "dotdot"), ("buffer", "lowercase"), ("normal", "file scheme"),
                      ("colour", "unc"), ("buffer", "nul")}
    fast_links = {("buffer", "folder link out"), ("colour", "hard link"), ("normal", "fifo"),
                  ("buffer", "link inside")}
    out = [Case("origins", f"{slot} {spelling}", _spelling(slot, spelling),
                (slot, spelling) in fast_spellings)
           for slot in _SLOTS for spelling in spellings(Path("/r"), "x")]
    out += [Case("origins", f"{slot} {link}", _linked(slot, link), (slot, link) in fast_links)
            for slot in _SLOTS for link in LINKS]
    return out


# ------------------------------------------------------------------------------------------------
# formats: what an image may be


def png(pixels: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    PILImage.fromarray(pixels).save(buffer, "PNG")
    return buffer.getvalue()


def encoded(kind: str, size: tuple[int, int] = (8, 8), **options) -> bytes:
    """An image of ``size`` (width, height) in pillow's format ``kind``."""
    buffer = io.BytesIO()
    image = PILImage.fromarray(checker(max(size), 2)[:size[1], :size[0]])
    image.save(buffer, kind, **options)
    return buffer.getvalue()


def ktx2(side: int = 16) -> bytes:
    """A valid UASTC KTX 2 of ``side``²."""
    import alktx2

    pixels = np.dstack([checker(side, 2), np.full((side, side), 255, np.uint8)])
    return alktx2.encode_raw_rgba_to_ktx2(pixels.tobytes(), side, side, False, codec="uastc")


def _ktx2_edit(edit: str) -> bytes:
    """A KTX 2 damaged as ``edit`` says: its level's bytes garbage or zero, its level index
    lying about the level's size, cut short, a cube map, or a header and nothing else."""
    data = bytearray(ktx2())
    offset, length, unpacked = struct.unpack_from("<QQQ", data, 80)
    if edit == "garbage body":
        data[offset:offset + length] = bytes(np.random.default_rng(1).integers(
            0, 256, length, np.uint8))
    elif edit == "lying level size":
        struct.pack_into("<QQQ", data, 80, offset, length * 4, unpacked * 4)
    elif edit == "half a level":
        struct.pack_into("<QQQ", data, 80, offset, length // 2, unpacked)
    elif edit == "cut short":
        data = data[:-100]
    elif edit == "cube map":
        struct.pack_into("<I", data, 36, 6)
    elif edit == "header only":
        data = bytearray(b"\xabKTX 20\xbb\r\n\x1a\n" + bytes(60))
    return bytes(data)


DISGUISES = {  # a file named .png that is something else: its first bytes, and what baker says
    "TIFF": (encoded("TIFF"), "a TIFF image"), "BMP": (encoded("BMP"), "a BMP image"),
    "GIF": (encoded("GIF"), "a GIF image"), "EPS": (b"%!PS-Adobe-3.0 EPSF-3.0\n" + bytes(64),
                                                    "an EPS image"),
    "PSD": (b"8BPS" + bytes(64), "a PSD image"), "DDS": (b"DDS " + bytes(124), "a DDS image"),
    "JPEG 2000": (b"\x00\x00\x00\x0cjP  \r\n\x87\n" + bytes(64), "a JPEG 2000 image"),
    "WebP as a core source": (encoded("WEBP"), "a WEBP image"),
    "not an image": (b"#!/bin/sh\nrm -rf ~\n", "not an image baker recognises"),
}


def _arithmetic_jpeg() -> bytes:
    """A JPEG whose frame header says arithmetic coding (SOF9 in place of SOF0)."""
    data = bytearray(encoded("JPEG"))
    data[data.index(b"\xff\xc0") + 1] = 0xC9
    return bytes(data)


def _damaged_png(edit: str) -> bytes:
    data = bytearray(png(checker(64, 4)))
    if edit == "IHDR damaged":
        data[16:24] = b"\x17" * 8
    elif edit == "cut short":
        data = data[:len(data) // 2]
    return bytes(data)


def _format(slot: str, data: Callable[[], bytes], name: str, code: tuple[int, ...],
            says: tuple[str, ...], extension: str | None = None) -> Callable[[Layout], Plan]:
    def make(layout: Layout) -> Plan:
        (layout.folder / name).write_bytes(data())
        layout.with_texture(name, slot, extension)
        return Plan(layout.bake(), code, says)
    return make


def _formats() -> list[Case]:
    out = []
    fast = {("normal", "TIFF"), ("colour", "EPS"), ("colour", "garbage body"),
            ("normal", "lying level size"), ("colour", "arithmetic JPEG")}
    for slot, key in TEXTURE_SLOTS.items():
        for kind, (data, says) in DISGUISES.items():
            out.append(Case("formats", f"{slot} {kind} named .png",
                            _format(key, lambda d=data: d, "albedo.png", (1,),
                                    ("images[0]", says)), (slot, kind) in fast))
        for edit in ("garbage body", "lying level size", "cut short", "cube map", "header only"):
            out.append(Case("formats", f"{slot} KTX 2 {edit}",
                            _format(key, lambda e=edit: _ktx2_edit(e), "albedo.ktx2", (1,),
                                    ("images[0]", "cannot decode"), "KHR_texture_basisu"),
                            (slot, edit) in fast))
        out.append(Case("formats", f"{slot} arithmetic JPEG",
                        _format(key, _arithmetic_jpeg, "albedo.jpg", (1,),
                                ("arithmetic-coded",)), (slot, "arithmetic JPEG") in fast))
        for edit in ("IHDR damaged", "cut short"):
            out.append(Case("formats", f"{slot} PNG {edit}",
                            _format(key, lambda e=edit: _damaged_png(e), "albedo.png", (1,),
                                    ("images[0]", "cannot decode"))))
        out.append(Case("formats", f"{slot} valid KTX 2",
                        _format(key, ktx2, "albedo.ktx2", (0,), (), "KHR_texture_basisu")))
        out.append(Case("formats", f"{slot} valid WebP",
                        _format(key, lambda: encoded("WEBP", lossless=True), "albedo.webp", (0,),
                                (), "EXT_texture_webp")))
        out.append(Case("formats", f"{slot} image of an unknown texture extension",
                        _format(key, lambda: encoded("PNG"), "albedo.png", (1,),
                                ("cannot be checked",), "ACME_texture_x")))
    return out


# ------------------------------------------------------------------------------------------------
# budgets: what an input may declare


@functools.lru_cache(maxsize=None)
def one_bit_png(width: int, height: int) -> bytes:
    """A valid 1-bit PNG of ``width`` × ``height`` black pixels (a few hundred bytes a Mpx)."""
    row = b"\0" + bytes(-(-width // 8))
    data = zlib.compress(row * height, 9)
    header = struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0)

    def chunk(kind: bytes, payload: bytes) -> bytes:
        return (struct.pack(">I", len(payload)) + kind + payload
                + struct.pack(">I", zlib.crc32(kind + payload)))
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", data) + chunk(b"IEND", b"")


@functools.lru_cache(maxsize=None)
def flat_webp(width: int, height: int) -> bytes:
    """A lossy WebP of ``width`` × ``height`` of one colour (a few hundred bytes)."""
    buffer = io.BytesIO()
    PILImage.new("RGB", (width, height), (90, 120, 150)).save(buffer, "WEBP", quality=50)
    return buffer.getvalue()


def webp_header(width: int, height: int) -> bytes:
    """A 38-byte lossless WebP whose header declares ``width`` × ``height`` (its body is not
    one: it is refused from the header, or does not decode)."""
    bits = (width - 1) | (height - 1) << 14
    chunk = b"\x2f" + bits.to_bytes(4, "little") + bytes(13)
    return b"RIFF" + struct.pack("<I", 12 + len(chunk)) + b"WEBPVP8L" + struct.pack(
        "<I", len(chunk)) + chunk


def jpeg_header(width: int, height: int, cut: int = 600) -> bytes:
    """A progressive JPEG whose frame header declares ``width`` × ``height``, cut to ``cut``
    bytes and ended (what libjpeg decodes, without a word, to grey where the data is missing)."""
    data = bytearray(encoded("JPEG", (64, 64), progressive=True))
    frame = data.index(b"\xff\xc2")
    struct.pack_into(">HH", data, frame + 5, height, width)
    return bytes(data[:cut - 2]) + b"\xff\xd9"


def _textured(files: dict[str, Callable[[], bytes]], code: tuple[int, ...],
              says: tuple[str, ...], extension: str | None = None) -> Callable[[Layout], Plan]:
    def make(layout: Layout) -> Plan:
        for name, data in files.items():
            (layout.folder / name).write_bytes(data())
        layout.textures(list(files), extension)
        return Plan(layout.bake(), code, says)
    return make


def _edited(edit: Callable[[Layout], None], code: tuple[int, ...],
            says: tuple[str, ...]) -> Callable[[Layout], Plan]:
    def make(layout: Layout) -> Plan:
        edit(layout)
        return Plan(layout.bake(), code, says)
    return make


def _meshopt_fallbacks(layout: Layout, count: int = 6) -> None:
    for _ in range(count):
        layout.json["buffers"].append({"byteLength": 1 << 30, "extensions": {
            "EXT_meshopt_compression": {"fallback": True}}})
    layout.json["extensionsUsed"] = ["EXT_meshopt_compression"]


def _sparse_bin(layout: Layout, size: int = 5 << 30) -> None:
    with open(layout.bin, "r+b") as stream:
        stream.truncate(size)
    layout.json["buffers"][0]["byteLength"] = size


def _unbacked(kind: str, count: int) -> Callable[[Layout], None]:
    """An accessor of ``count`` elements without a bufferView (no data) as the indices, the
    positions or the GPU instances' translations."""
    def edit(layout: Layout) -> None:
        accessors, primitive = layout.json["accessors"], layout.json["meshes"][0]["primitives"][0]
        accessors.append({"componentType": 5125 if kind == "indices" else 5126,
                          "count": count, "type": "SCALAR" if kind == "indices" else "VEC3"})
        if kind == "indices":
            primitive["indices"] = len(accessors) - 1
        elif kind == "positions":
            primitive["attributes"] = {"POSITION": len(accessors) - 1}
            primitive.pop("indices")
        else:
            layout.json["nodes"][0]["extensions"] = {"EXT_mesh_gpu_instancing": {
                "attributes": {"TRANSLATION": len(accessors) - 1}}}
            layout.json["extensionsUsed"] = ["EXT_mesh_gpu_instancing"]
    return edit


def _node_chain(length: int) -> Callable[[Layout], None]:
    def edit(layout: Layout) -> None:
        nodes = layout.json["nodes"]
        first = len(nodes)
        nodes += [{"children": [first + i + 1]} for i in range(length - 1)] + [{"children": [0]}]
        layout.json["scenes"][0]["nodes"] = [first]
    return edit


def _flat_nodes(count: int) -> Callable[[Layout], None]:
    def edit(layout: Layout) -> None:
        first = len(layout.json["nodes"])
        layout.json["nodes"] += [{} for _ in range(count)]
        layout.json["scenes"][0]["nodes"] += list(range(first, first + count))
    return edit


def _zero_indices(count: int) -> Callable[[Layout], None]:
    """``count`` uint8 indices, all 0, in the buffer: degenerate triangles backed by data."""
    def edit(layout: Layout) -> None:
        data = layout.bin.read_bytes()
        layout.bin.write_bytes(data + bytes(count))
        layout.json["buffers"][0]["byteLength"] = len(data) + count
        layout.json["bufferViews"].append({"buffer": 0, "byteOffset": len(data),
                                           "byteLength": count})
        layout.json["accessors"].append({"bufferView": len(layout.json["bufferViews"]) - 1,
                                         "componentType": 5121, "count": count,
                                         "type": "SCALAR"})
        layout.json["meshes"][0]["primitives"][0]["indices"] = len(layout.json["accessors"]) - 1
    return edit


def _budgets() -> list[Case]:
    big = "more than baker decodes of one image"
    return [
        Case("budgets", "six meshopt fallback buffers of 1 GiB",
             _edited(_meshopt_fallbacks, (1,), ("compressed geometry",)), True),
        Case("budgets", "a sparse 5 GiB bin", _edited(_sparse_bin, (1,), ("take the input past",)),
             True),
        Case("budgets", "a 3 GiB byteLength on a 152-byte bin",
             _edited(lambda layout: layout.json["buffers"][0].update(byteLength=3 << 30), (1,),
                     ("take the input past",))),
        Case("budgets", "four 1-bit PNGs of 16384x8192",
             _textured({f"t{k}.png": lambda: one_bit_png(16384, 8192) for k in range(4)}, (1,),
                       (big,)), True),
        Case("budgets", "five 38-byte WebPs of 16383x8192",
             _textured({f"t{k}.webp": lambda: webp_header(16383, 8192) for k in range(5)}, (1,),
                       (big,), "EXT_texture_webp"), True),
        Case("budgets", "five 38-byte WebPs of 8192x4096",
             _textured({f"t{k}.webp": lambda: webp_header(8192, 4096) for k in range(5)}, (1,),
                       ("cannot decode",), "EXT_texture_webp")),
        Case("budgets", "two colour WebPs of 8192x4096, the most kept",
             _textured({f"t{k}.webp": lambda: flat_webp(8192, 4096) for k in range(2)}, (0,),
                       (), "EXT_texture_webp")),
        Case("budgets", "three colour PNGs of 8192x4096, one left out",
             _textured({f"t{k}.png": lambda: one_bit_png(8192, 4096) for k in range(3)}, (0,),
                       ())),
        Case("budgets", "nine PNGs of 8192x4096, past the scene's pixels",
             _textured({f"t{k}.png": lambda: one_bit_png(8192, 4096) for k in range(9)}, (1,),
                       ("pixels in all",))),
        Case("budgets", "a 600-byte progressive JPEG of 8192x4096",
             _textured({"t.jpg": lambda: jpeg_header(8192, 4096)}, (1,),
                       ("fewer than a JPEG needs",)), True),
        Case("budgets", "a 600-byte progressive JPEG of 16384x8192",
             _textured({"t.jpg": lambda: jpeg_header(16384, 8192)}, (1,), (big,))),
        Case("budgets", "an index accessor of 30 M without data",
             _edited(_unbacked("indices", 30_000_000), (1,), ("without a bufferView",)), True),
        Case("budgets", "80 M vertices without data",
             _edited(_unbacked("positions", 80_000_000), (1,), ("without a bufferView",))),
        Case("budgets", "100 M GPU instances without data",
             _edited(_unbacked("instances", 100_000_000), (1,), ("without a bufferView",))),
        Case("budgets", "a chain of a million nodes",
             _edited(_node_chain(1_000_000), (1,), ("nodes, more than",))),
        Case("budgets", "a chain of 5000 nodes",
             _edited(_node_chain(5000), (1,), ("nested 4,097 deep",)), True),
        Case("budgets", "300,000 nodes", _edited(_flat_nodes(300_000), (1,), ("nodes, more than",))),
        Case("budgets", "a megabyte of zero indices",
             _edited(_zero_indices(1 << 20), (0, 1, 4), ())),
    ]


# ------------------------------------------------------------------------------------------------
# state: what a bake state beside the scene may say


def edit_state(path: Path, change: Callable[[dict, dict], object]) -> None:
    """Rewrite the bake state at ``path`` with ``change(header, arrays)`` applied (the header's
    JSON, every ``.npy`` member as an array), CRCs recomputed as an attacker would."""
    import zipfile

    with zipfile.ZipFile(path) as archive:
        header = json.loads(archive.read("header.json"))
        members = {name: archive.read(name) for name in archive.namelist()
                   if name != "header.json"}
    change(header, members)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as archive:
        archive.writestr("header.json", json.dumps(header))
        for name, data in members.items():
            archive.writestr(name, data)


def _asked(**values) -> Callable[[dict, dict], None]:
    return lambda header, members: header["fingerprints"]["asked"].update(values)


def _hook_state(change: Callable[[dict, dict], None], code: tuple[int, ...], says: tuple[str, ...],
                link: bool = True, command: str = "hook") -> Callable[[Layout], Plan]:
    """A hook (or rebake) run on a scene whose bake state was edited by ``change``; ``link``:
    its buffer is then a hard link to the decoy beside the folder (what a state saying
    ``allow_hard_links`` would let through)."""
    def make(layout: Layout) -> Plan:
        output = layout.folder / "scene_baked.gltf"
        first = (["hook", str(layout.save()), *FAST[:-1]] if command == "hook"
                 else layout.bake(output=output))

        def edit() -> None:
            edit_state(output.with_name(output.name + ".bake"), change)
            if link:
                os.link(layout.root / "secret.bin", layout.folder / "linked.bin")
                layout.json["buffers"][0].update(uri="linked.bin", byteLength=(
                    layout.root / "secret.bin").stat().st_size)
                layout.save()
        argv = (["hook", str(layout.gltf)] if command == "hook"
                else ["rebake", str(layout.gltf), "-o", str(output), "--quiet"])
        return Plan(argv, code, says, place=layout.folder, before=[first], edit=edit)
    return make


def _state_file(kind: str) -> Callable[[Layout], Plan]:
    """``OUT.bake`` replaced by a FIFO nothing reads, a link to /dev/zero, a deflate bomb."""
    def make(layout: Layout) -> Plan:
        state = layout.out / "baked.glb.bake"

        def edit() -> None:
            state.unlink()
            if kind == "fifo":
                os.mkfifo(state)
            elif kind == "link to /dev/zero":
                state.symlink_to("/dev/zero")
            else:
                from tests.test_hostile import deflate_bomb
                state.write_bytes(deflate_bomb(b"header.json", 3))
        code, says = {"fifo": ((1,), ("nothing reads",)),
                      "link to /dev/zero": ((1,), ("symbolic link",)),
                      "deflate bomb": ((0,), ())}[kind]
        return Plan(layout.bake(), code, says, before=[layout.bake()], edit=edit)
    return make


def _named_as_output(name: str) -> Callable[[Layout], Plan]:
    """The scene's buffer is a file named as a file of the bake (``baked.glb.bake``, …) beside
    an output in the scene's folder."""
    def make(layout: Layout) -> Plan:
        layout.bin.rename(layout.folder / name)
        layout.json["buffers"][0]["uri"] = name
        return Plan(layout.bake(output=layout.folder / "baked.glb"), (1,),
                    ("which the scene reads", "buffers[0].uri"), place=layout.folder)
    return make


def _state() -> list[Case]:
    return [
        Case("state", "hook: the state allows hard links",
             _hook_state(_asked(allow_hard_links=True), (1,), ("2 names",)), True),
        Case("state", "rebake: the state allows hard links",
             _hook_state(_asked(allow_hard_links=True), (1,), ("2 names",), command="rebake")),
        Case("state", "hook: the state names a cluster",
             _hook_state(_asked(cluster="127.0.0.1:9"), (0,), (), link=False)),
        Case("state", "hook: the state raises the budgets",
             _hook_state(_asked(max_total_rays=10 ** 18, chunk_texels=10 ** 9, threads=4096),
                         (0,), (), link=False)),
        Case("state", "the state a FIFO nothing reads", _state_file("fifo")),
        Case("state", "the state a link to /dev/zero", _state_file("link to /dev/zero")),
        Case("state", "the state a deflate bomb", _state_file("deflate bomb")),
        Case("state", "a buffer named as the state", _named_as_output("baked.glb.bake"), True),
        Case("state", "a buffer named as the state's timing",
             _named_as_output("baked.glb.bake.json")),
        Case("state", "a buffer named as the output's .bin",
             lambda layout: _gltf_bin_over_input(layout)),
    ]


def _gltf_bin_over_input(layout: Layout) -> Plan:
    """A .gltf output in the scene's folder whose .bin is the scene's buffer."""
    layout.bin.rename(layout.folder / "baked.bin")
    layout.json["buffers"][0]["uri"] = "baked.bin"
    return Plan(layout.bake(output=layout.folder / "baked.gltf"), (1,),
                ("which the scene reads", "--overwrite"), place=layout.folder)


# ------------------------------------------------------------------------------------------------
# hook: what a repository may hold


def _hook(setup: Callable[[Layout], None], code: tuple[int, ...], says: tuple[str, ...],
          scene: str = "scene.gltf") -> Callable[[Layout], Plan]:
    def make(layout: Layout) -> Plan:
        layout.save()
        setup(layout)
        return Plan(["hook", str(layout.folder / scene), *FAST[:-1]], code, says,
                    place=layout.folder)
    return make


def _gitignore(kind: str) -> Callable[[Layout], None]:
    def setup(layout: Layout) -> None:
        path = layout.folder / ".gitignore"
        if kind == "link out":
            path.symlink_to(layout.root / "secret.txt")
        elif kind == "hard link out":
            os.link(layout.root / "secret.txt", path)
        elif kind == "sparse 3 GB":
            with open(path, "wb") as stream:
                stream.truncate(3 << 30)
        elif kind == "fifo":
            os.mkfifo(path)
        elif kind == "folder":
            path.mkdir()
    return setup


def _staged_link(layout: Layout) -> None:
    """The staged scene a link to a scene outside the folder (beside the decoys)."""
    outside = layout.root / "elsewhere.gltf"
    layout.gltf.rename(outside)
    layout.json["buffers"][0]["uri"] = "scene/scene.bin"
    outside.write_text(json.dumps(layout.json))
    (layout.folder / "staged.gltf").symlink_to(outside)


def _output_link(name: str) -> Callable[[Layout], None]:
    def setup(layout: Layout) -> None:
        (layout.folder / name).symlink_to(layout.root / "secret.txt")
    return setup


def _hooks() -> list[Case]:
    said = "not changed"
    return [Case("hook", f".gitignore {kind}", _hook(_gitignore(kind), (OUTPUTS_CHANGED,), (said,)),
                 kind in ("link out", "sparse 3 GB"))
            for kind in ("link out", "hard link out", "sparse 3 GB", "fifo", "folder")] + [
        Case("hook", "a staged scene linked from outside",
             _hook(_staged_link, (1,), ("leads out of the scene's folder",), "staged.gltf"), True),
        Case("hook", "the output a link out",
             _hook(_output_link("scene_baked.gltf"), (1,), ("symbolic link",))),
        Case("hook", "the state a link out",
             _hook(_output_link("scene_baked.gltf.bake"), (1,), ("symbolic link",))),
    ]


# ------------------------------------------------------------------------------------------------
# faults: signals at any moment, outputs that are not files


def _interrupted(signal_number: int, after: float, heavy: bool) -> Callable[[Layout], Plan]:
    """A bake (``heavy``: of two 8192×4096 WebP colour textures, seconds of decoding) sent a
    signal ``after`` seconds in: it ends within 2 s, 130 or 143, or had ended already."""
    def make(layout: Layout) -> Plan:
        if heavy:
            names = [f"t{k}.webp" for k in range(2)]
            for name in names:
                (layout.folder / name).write_bytes(flat_webp(8192, 4096))
            layout.textures(names, "EXT_texture_webp")
        expected = 130 if signal_number == signal.SIGINT else 143
        return Plan(layout.bake(), (expected, 0), (), signal=signal_number, after=after)
    return make


def _report(kind: str) -> Callable[[Layout], Plan]:
    """``--report`` at a link to a FIFO (read, or read by nothing), to a file outside the
    output's place, to /dev/null; or a folder."""
    def make(layout: Layout) -> Plan:
        report = layout.out / "report.json"
        code, says, reader = (1,), (), None
        if kind in ("fifo read", "fifo unread"):
            fifo = layout.out / "pipe"
            os.mkfifo(fifo)
            report.symlink_to(fifo)
            if kind == "fifo read":
                code, reader = (0,), fifo
            else:
                says = ("nothing reads",)
        elif kind == "link out":
            report.symlink_to(layout.root / "secret.txt")
            says = ("symbolic link",)
        elif kind == "link to /dev/null":
            report.symlink_to("/dev/null")
            says = ("a character device",)
        elif kind == "folder":
            report.mkdir()
            says = ("a folder",)
        return Plan(layout.bake("--report", str(report)), code, says, reader=reader,
                    streams=b"{")
    return make


def _faults(long: bool) -> list[Case]:
    out = [Case("faults", "SIGTERM 1.5 s into decoding", _interrupted(signal.SIGTERM, 1.5, True),
                True),
           Case("faults", "SIGINT 2 s into decoding", _interrupted(signal.SIGINT, 2.0, True), True),
           Case("faults", "report streamed to a FIFO", _report("fifo read"), True),
           Case("faults", "report at a link out", _report("link out"), True)]
    out += [Case("faults", f"report {kind}", _report(kind))
            for kind in ("fifo unread", "link to /dev/null", "folder")]
    if long:
        for number in (signal.SIGTERM, signal.SIGINT):
            for heavy in (True, False):
                for tenth in range(1, 41, 3 if heavy else 2):
                    out.append(Case("faults", f"{signal.Signals(number).name} at {tenth / 10} s"
                                              f"{' decoding' if heavy else ''}",
                                    _interrupted(number, tenth / 10, heavy)))
    return out


def prepare(case: Case, root: Path, run: Callable[[list[str]], dict]) -> tuple[Layout, Plan]:
    """The layout of ``case`` under ``root`` and its plan, once the commands it runs first
    (``Plan.before``, through ``run``: each must succeed; a hook's first bake says it wrote
    files to commit) and its edit are done."""
    layout = Layout(root)
    plan = case.make(layout)
    for argv in plan.before:
        result = run(argv)
        assert result["code"] in ((0, OUTPUTS_CHANGED) if argv[0] == "hook" else (0,)), (
            argv, result["err"])
    if plan.edit is not None:
        plan.edit()
    return layout, plan


def cases(long: bool = False) -> list[Case]:
    """Every case of every family (``long``), or the fast set."""
    everything = _origins() + _formats() + _budgets() + _state() + _hooks() + _faults(long)
    return everything if long else [case for case in everything if case.fast]
