"""Texture images: their headers read and checked first, then decoded in the formats glTF allows.

glTF allows PNG and JPEG for ``texture.source``; WebP only through ``EXT_texture_webp``, KTX 2
(Basis Universal) only through ``KHR_texture_basisu`` and AVIF only through
``EXT_texture_avif`` (``FORMATS``). An image is opened only as one of the formats its
references allow, so a TIFF, BMP, GIF or EPS file named ``.png`` is refused by its real kind
(told from its first bytes, never parsed), and no other decoder of pillow's (EPS would run
Ghostscript) is ever reached.

``header`` reads what an image will cost from its header alone, for every image of the scene
before any is decoded (``gltf.budget.check_pixels`` adds them up):

- its pixels (a KTX 2's every mip level), at most ``MAX_IMAGE_PIXELS``;
- whether its bytes can hold them: deflate packs at most 1032 bytes into one (zlib's limit),
  so a 715-byte PNG declaring 16384×8192 is cut short; a JPEG codes every 8×8 block of its
  full-resolution component in at least one bit (its DC coefficient, Huffman-coded), so it has
  at least w·h/512 bytes — a 600-byte progressive JPEG declaring 16384×8192, which libjpeg
  would decode to grey without an error, is cut short too; arithmetic-coded, lossless and
  hierarchical JPEGs (which glTF viewers do not decode either) are refused. WebP, KTX 2 and
  AVIF can code a flat image in a few bytes: their pixels count against the budget alone.

``decode`` then decodes an image whole: to (h, w, 4) RGBA when the bake samples it, or only to
check it when the output merely carries it (a normal map, an unused image): every image an
output carries has been decoded once. KTX 2 is transcoded, every level, by the
``opengl-basisu`` package (``pip install "baker[ktx2]"``); without it, ``Undecodable`` says
so, and its header alone is checked.
"""

from __future__ import annotations

import io
import struct
import warnings
import zlib
from dataclasses import dataclass

import numpy as np
from PIL import Image as PILImage

from baker.errors import InputError
from baker.run.interruptible import call_interruptibly

MAX_IMAGE_PIXELS = 1 << 25
"""Most pixels of one image decoded (8192 × 4096: 128 MiB as RGBA; a KTX 2's levels together):
decoding one holds up to three times that (a WebP's pixels as decoded, pillow's image of them,
the array)."""
FORMATS = {None: ("PNG", "JPEG"), "EXT_texture_webp": ("WEBP",),
           "KHR_texture_basisu": ("KTX2",), "EXT_texture_avif": ("AVIF",)}
"""The image formats glTF allows a texture's source to have, by the extension naming it."""
ANY_FORMAT = ("PNG", "JPEG", "WEBP", "KTX2", "AVIF")
"""The formats an image no texture uses may have (those of every source above)."""
KTX2_EXTRA = 'pip install "baker[ktx2]"'
_DEFLATE_RATIO = 1032  # zlib's most bytes out per byte in
_JPEG_PIXELS_PER_BYTE = 512  # 8×8 pixels a block, a bit at least a block
_SIGNATURES = (
    (b"\x89PNG\r\n\x1a\n", "PNG"),
    (b"\xff\xd8\xff", "JPEG"),
    (b"\xabKTX 20\xbb\r\n\x1a\n", "KTX2"),
    (b"GIF87a", "GIF"),
    (b"GIF89a", "GIF"),
    (b"BM", "BMP"),
    (b"II*\x00", "TIFF"),
    (b"MM\x00*", "TIFF"),
    (b"%!PS", "EPS"),
    (b"\xc5\xd0\xd3\xc6", "EPS"),
    (b"8BPS", "PSD"),
    (b"\x00\x00\x00\x0cjP  ", "JPEG 2000"),
    (b"DDS ", "DDS"),
)
_FIX = "re-save the image as PNG or JPEG and export again"
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}  # IHDR colour type → samples a pixel
_PACKED = {"RGB": "RGBX", "RGBA": "RGBA"}  # modes pillow packs as RGBA bytes (RGB: alpha 255)
_JPEG_HUFFMAN = {0xC0, 0xC1, 0xC2}  # baseline, extended, progressive: what viewers decode
_JPEG_OTHER = {0xC3: "lossless", 0xC5: "hierarchical", 0xC6: "hierarchical",
               0xC7: "hierarchical", 0xC9: "arithmetic-coded", 0xCA: "arithmetic-coded",
               0xCB: "arithmetic-coded", 0xCD: "arithmetic-coded", 0xCE: "arithmetic-coded",
               0xCF: "arithmetic-coded"}


class Undecodable(InputError):
    """An image in an allowed format that this installation cannot decode (KTX 2 without its
    package)."""


@dataclass(frozen=True)
class Header:
    """What an image's header says: its format, the size of its first level, and the pixels
    decoding all of it takes (every level of a KTX 2)."""

    kind: str
    width: int
    height: int
    pixels: int


def kind(data: bytes) -> str | None:
    """The image format of ``data`` from its first bytes (PNG, JPEG, WEBP, KTX2, AVIF, GIF, …)."""
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "WEBP"
    if data[4:12] in (b"ftypavif", b"ftypavis"):
        return "AVIF"
    return next((name for signature, name in _SIGNATURES if data.startswith(signature)), None)


def header(data: bytes, allowed: tuple[str, ...], label: str, file: str, where: str) -> Header:
    """The header of the image ``data`` (``label`` names it in messages), which must be in one of
    the ``allowed`` formats (``FORMATS``) and hold its pixels (see the module's docstring); an
    ``InputError`` at ``where`` otherwise. Nothing is decoded."""
    found = kind(data)
    if found not in allowed:
        article = "an" if found and found[0] in "AEIOU" else "a"
        what = f"{article} {found} image" if found else "not an image baker recognises"
        if not allowed:
            raise InputError(f"{label} is {what}, named only by a texture extension baker does "
                             "not know: it cannot be checked", file=file, where=where,
                             fix="re-export the textures as PNG or JPEG")
        core = allowed == FORMATS[None]
        via = "glTF allows a texture's source to be" if core else "its textures allow"
        other = (" (WebP only through EXT_texture_webp, KTX 2 only through KHR_texture_basisu)"
                 if core else "")
        raise InputError(f"{label} is {what}; {via} {' or '.join(allowed)} only{other}",
                         file=file, where=where, fix=_FIX)
    try:
        head = _READERS[found](data)
    except (struct.error, IndexError):
        raise InputError(f"cannot decode {label} (its {found} header is cut short)", file=file,
                         where=where, fix=_FIX) from None
    except ValueError as exc:
        raise InputError(f"cannot decode {label} ({exc})", file=file, where=where,
                         fix=_FIX) from None
    if head.width <= 0 or head.height <= 0:
        raise InputError(f"{label} declares {head.width}×{head.height} pixels", file=file,
                         where=where, fix=_FIX)
    if head.pixels > MAX_IMAGE_PIXELS:
        raise InputError(f"{label} is {head.width}×{head.height} = {head.pixels:,} pixels, more "
                         f"than baker decodes of one image (at most {MAX_IMAGE_PIXELS:,}, e.g. "
                         f"8192×4096: {4 * MAX_IMAGE_PIXELS >> 20} MiB as RGBA)", file=file,
                         where=where, fix="downscale the texture (4096×4096 is plenty for a "
                                          "lightmap bake) and export again")
    _check_fits(data, head, label, file, where)
    return head


def _check_fits(data: bytes, head: Header, label: str, file: str, where: str) -> None:
    """Refuse a PNG or JPEG whose declared pixels cannot be in its bytes (see the module)."""
    if head.kind == "PNG":
        depth, colour = data[24], data[25]
        raw = head.height * (1 + -(-head.width * depth * _PNG_CHANNELS.get(colour, 4) // 8))
        if raw > _DEFLATE_RATIO * len(data):
            raise InputError(f"{label} declares {head.width}×{head.height} pixels ({raw:,} bytes) "
                             f"but has only {len(data):,} bytes, which deflate cannot unpack to "
                             f"more than {_DEFLATE_RATIO * len(data):,}: it is cut short or damaged",
                             file=file, where=where, fix=_FIX)
    if head.kind == "JPEG" and head.pixels > _JPEG_PIXELS_PER_BYTE * len(data):
        raise InputError(f"{label} declares {head.width}×{head.height} pixels but has only "
                         f"{len(data):,} bytes, fewer than a JPEG needs for them (a bit at "
                         f"least for each 8×8 block: {head.pixels // _JPEG_PIXELS_PER_BYTE:,} "
                         "bytes): it is cut short or damaged", file=file, where=where, fix=_FIX)


def _png(data: bytes) -> Header:
    """The size of a PNG, from its IHDR chunk (the first, its CRC checked)."""
    length, name = struct.unpack_from(">I4s", data, 8)
    if name != b"IHDR" or length != 13:
        raise ValueError("its PNG header has no IHDR chunk first")
    if struct.unpack_from(">I", data, 29)[0] != zlib.crc32(data[12:29]):
        raise ValueError("its PNG header is damaged: the IHDR chunk's CRC does not match")
    width, height = struct.unpack_from(">II", data, 16)
    return Header("PNG", width, height, width * height)


def _jpeg(data: bytes) -> Header:
    """The frame header (SOF) of a JPEG, found by walking its marker segments."""
    at = 2
    while True:
        while data[at] != 0xFF or data[at + 1] == 0xFF:  # fill bytes before a marker
            at += 1
        marker = data[at + 1]
        if marker in _JPEG_HUFFMAN or marker in _JPEG_OTHER:
            if marker in _JPEG_OTHER:
                raise ValueError(f"it is {_JPEG_OTHER[marker]}, which glTF viewers do not "
                                 "decode")
            height, width = struct.unpack_from(">HH", data, at + 5)
            return Header("JPEG", width, height, width * height)
        if marker in (0xD9, 0xDA):
            raise ValueError("its JPEG has no frame header before the image data")
        at += 2 + struct.unpack_from(">H", data, at + 2)[0]


def _webp(data: bytes) -> Header:
    """The canvas of a WebP: its VP8 (lossy), VP8L (lossless) or VP8X (extended) header."""
    chunk = data[12:16]
    if chunk == b"VP8 ":
        if data[23:26] != b"\x9d\x01\x2a":
            raise ValueError("its VP8 header has no start code")
        width, height = (v & 0x3FFF for v in struct.unpack_from("<HH", data, 26))
    elif chunk == b"VP8L":
        if data[20] != 0x2F:
            raise ValueError("its VP8L header has no signature")
        bits = int.from_bytes(data[21:25], "little")
        width, height = (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
    elif chunk == b"VP8X":
        width = int.from_bytes(data[24:27], "little") + 1
        height = int.from_bytes(data[27:30], "little") + 1
    else:
        raise ValueError(f"its WebP has no VP8, VP8L or VP8X header (it has {chunk!r})")
    return Header("WEBP", width, height, width * height)


def _ktx2(data: bytes) -> Header:
    """A KTX 2's first level and every level's pixels; only 2D textures (no cube map, array or
    volume: ``KHR_texture_basisu``)."""
    width, height, depth, layers, faces, levels = struct.unpack_from("<6I", data, 20)
    if depth or layers > 1 or faces != 1:
        raise ValueError(f"its KTX 2 header declares no 2D texture ({depth} deep, {layers} "
                         f"layers, {faces} faces): KHR_texture_basisu allows only 2D textures")
    if levels > 32:
        raise ValueError(f"its KTX 2 header declares {levels} mip levels")
    pixels = sum(max(width >> k, 1) * max(height >> k, 1) for k in range(max(levels, 1)))
    return Header("KTX2", width, height, pixels)


def _avif(data: bytes) -> Header:
    """The largest image an AVIF declares (its ``ispe`` properties: every item's size)."""
    sizes, at = [], data.find(b"ispe")
    while at >= 0:
        sizes.append(struct.unpack_from(">II", data, at + 8))
        at = data.find(b"ispe", at + 4)
    if not sizes:
        raise ValueError("its AVIF declares no image size (ispe)")
    width, height = max(sizes, key=lambda s: s[0] * s[1])
    return Header("AVIF", width, height, width * height)


_READERS = {"PNG": _png, "JPEG": _jpeg, "WEBP": _webp, "KTX2": _ktx2, "AVIF": _avif}


def decode(data: bytes, head: Header, label: str, file: str, where: str,
           keep: bool = True) -> np.ndarray | None:
    """Decode the image ``data`` whose ``header`` was read: (h, w, 4) uint8 RGBA, row 0 at the
    top, values as stored (sRGB), when ``keep``; else only decoded whole, to check it, and
    None. An ``InputError`` when it does not decode, ``Undecodable`` when this installation
    cannot decode its format."""
    if head.kind == "KTX2":
        return _transcoded(data, head, label, file, where, keep)
    try:
        with warnings.catch_warnings():  # baker has its own limits
            warnings.simplefilter("ignore", PILImage.DecompressionBombWarning)
            opened = PILImage.open(io.BytesIO(data), formats=[head.kind])
            with opened:
                if opened.size[0] * opened.size[1] > head.pixels:
                    raise ValueError(f"decodes to {opened.size[0]}×{opened.size[1]}, more than "
                                     f"its header declares ({head.width}×{head.height})")
                call_interruptibly(opened.load)  # a signal is not held up by the decoder
                return _rgba(opened) if keep else None
    except (OSError, ValueError, SyntaxError, EOFError, struct.error,
            PILImage.DecompressionBombError) as exc:
        raise InputError(f"cannot decode {label} ({exc})", file=file, where=where,
                         fix=_FIX) from None


def _rgba(image: PILImage.Image) -> np.ndarray:
    """A pillow image as (h, w, 4) uint8 RGBA; 16-bit greyscale keeps its high byte. Made a
    band of rows at a time (RGB and RGBA packed straight, the other modes converted): at most
    the image as decoded and the array at once (converting it whole, then copying, held five
    times its pixels' bytes)."""
    if image.mode.startswith("I"):
        high = (np.asarray(image) >> 8).clip(0, 255).astype(np.uint8)
        image = PILImage.fromarray(high, "L")
    width, height = image.size
    raw = _PACKED.get(image.mode)
    out = np.empty((height, width, 4), np.uint8)
    band = max(1, (1 << 21) // width)  # rows at once: 8 MiB as RGBA
    for top in range(0, height, band):
        rows = image.crop((0, top, width, min(top + band, height)))
        out[top:top + rows.size[1]] = (
            np.frombuffer(rows.tobytes("raw", raw), np.uint8).reshape(rows.size[1], width, 4)
            if raw else np.asarray(rows.convert("RGBA")))
    return out


def _transcoded(data: bytes, head: Header, label: str, file: str, where: str,
                keep: bool) -> np.ndarray | None:
    """A KTX 2 / Basis Universal image's every level transcoded to RGBA8 by opengl-basisu, the
    first kept when ``keep``."""
    try:
        import opengl_basisu
    except ImportError:
        raise Undecodable(f"{label} is KTX 2 (Basis Universal), which needs the opengl-basisu "
                          "package, not installed", file=file, where=where,
                          fix=f"{KTX2_EXTRA}, or export the textures as PNG or JPEG") from None
    try:
        texture = opengl_basisu.open(data)
        if (texture.width, texture.height) != (head.width, head.height) or texture.is_video:
            raise ValueError(f"decodes to {texture.width}×{texture.height}, its header says "
                             f"{head.width}×{head.height}")
        first = None
        for level in range(texture.levels):
            pixels = call_interruptibly(texture.transcode, "rgba8", level).data
            if level == 0 and keep:
                first = np.asarray(pixels, dtype=np.uint8)
    except (opengl_basisu.BasisuError, ValueError) as exc:
        raise InputError(f"cannot decode {label} ({exc})", file=file, where=where,
                         fix="encode the texture again (KTX-Software's toktx, gltf-transform)"
                         ) from None
    if first is None:
        return None
    return np.ascontiguousarray(first[::-1] if texture.y_flipped else first)
