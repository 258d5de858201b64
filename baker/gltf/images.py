"""Texture images decoded in the formats glTF allows them, within a pixel budget.

glTF allows PNG and JPEG for ``texture.source``; WebP only through ``EXT_texture_webp`` and
KTX 2 (Basis Universal) only through ``KHR_texture_basisu``. ``decode`` opens an image only as
one of the formats its reference allows (``FORMATS``), so a TIFF, BMP, GIF or EPS file named
``.png`` is refused by its real kind (told from its first bytes, never parsed), and no other
decoder of pillow's (EPS would run Ghostscript) is ever reached.

What it may cost is checked from the header, before any pixel is decoded:

- an image of more than ``MAX_IMAGE_PIXELS`` pixels is refused (``TooLarge``);
- a PNG whose pixels could not fit in its bytes is refused as damaged: deflate packs at most
  1032 bytes into one (zlib's limit), so a 715-byte PNG declaring 16384×8192 is cut short, and
  decoding it would only allocate 512 MiB for nothing;
- the caller's remaining budget for the scene (``MAX_SCENE_PIXELS`` in all) is checked, and
  ``OverBudget`` raised past it, so the texture can be left out with a warning.

KTX 2 is transcoded to RGBA8 by the ``opengl-basisu`` package (``pip install "baker[ktx2]"``);
without it, ``Undecodable`` says so and the texture is left out (its factor used).
"""

from __future__ import annotations

import io
import re
import struct
import warnings

import numpy as np
from PIL import Image as PILImage

from baker.errors import InputError

MAX_IMAGE_PIXELS = 16384 * 8192
"""Largest colour texture decoded (512 MiB as RGBA); larger ones are refused from their header."""
MAX_SCENE_PIXELS = 1 << 29
"""Most pixels of all a scene's colour textures together (2 GiB as RGBA, 32 textures of
4096²); the textures past it are left out with a warning."""
FORMATS = {None: ("PNG", "JPEG"), "EXT_texture_webp": ("WEBP",), "KHR_texture_basisu": ("KTX2",)}
"""The image formats glTF allows a texture's source to have, by the extension naming it."""
KTX2_EXTRA = 'pip install "baker[ktx2]"'
_DEFLATE_RATIO = 1032  # zlib's most bytes out per byte in
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


class TooLarge(InputError):
    """An image of more pixels than baker decodes."""


class OverBudget(InputError):
    """An image that would take the scene's textures past ``MAX_SCENE_PIXELS``."""


class Undecodable(InputError):
    """An image in an allowed format that this installation cannot decode (KTX 2 without its
    package)."""


def kind(data: bytes) -> str | None:
    """The image format of ``data`` from its first bytes (PNG, JPEG, WEBP, KTX2, GIF, …)."""
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "WEBP"
    if data[4:12] in (b"ftypavif", b"ftypavis"):
        return "AVIF"
    return next((name for signature, name in _SIGNATURES if data.startswith(signature)), None)


def decode(data: bytes, extension: str | None, label: str, budget: int, file: str,
           where: str) -> np.ndarray:
    """``data`` as (h, w, 4) uint8 RGBA, row 0 at the top, values as stored (sRGB), if it is in
    a format ``FORMATS[extension]`` allows and has at most ``budget`` pixels (the scene's
    remaining budget). ``label`` names the image in messages."""
    allowed = FORMATS[extension]
    found = kind(data)
    if found not in allowed:
        via = f"{extension} allows" if extension else "glTF allows a texture's source to be"
        article = "an" if found and found[0] in "AEIOU" else "a"
        what = f"{article} {found} image" if found else "not an image baker recognises"
        other = (" (WebP only through EXT_texture_webp, KTX 2 only through KHR_texture_basisu)"
                 if extension is None else "")
        raise InputError(f"{label} is {what}; {via} {' or '.join(allowed)} only{other}",
                         file=file, where=where, fix=_FIX)
    if found == "KTX2":
        return _ktx2(data, label, budget, file, where)
    try:
        with warnings.catch_warnings():  # baker has its own limits
            warnings.simplefilter("ignore", PILImage.DecompressionBombWarning)
            with PILImage.open(io.BytesIO(data), formats=[found]) as opened:
                _check_size(opened.size, label, budget, file, where)
                if found == "PNG":
                    _check_png_fits(opened, len(data), label, file, where)
                opened.load()
                return _rgba(opened)
    except PILImage.DecompressionBombError as exc:
        pixels = re.search(r"\((\d+) pixels\)", str(exc))
        size = f"{int(pixels.group(1)):,} pixels" if pixels else "too many pixels"
        raise _too_large(f"{label} has {size}", file, where) from None
    except (OSError, ValueError, SyntaxError, EOFError, struct.error) as exc:
        raise InputError(f"cannot decode {label} ({exc})", file=file, where=where,
                         fix=_FIX) from None


def _check_size(size: tuple[int, int], label: str, budget: int, file: str, where: str) -> None:
    """Refuse, from the header alone, an image past ``MAX_IMAGE_PIXELS`` or the budget."""
    width, height = size
    pixels = width * height
    if pixels > MAX_IMAGE_PIXELS:
        raise _too_large(f"{label} is {width}×{height} = {pixels:,} pixels", file, where)
    if pixels > budget:
        raise OverBudget(
            f"{label} ({width}×{height}) would take the scene's colour textures past "
            f"{MAX_SCENE_PIXELS:,} pixels ({4 * MAX_SCENE_PIXELS >> 20} MiB as RGBA)",
            file=file, where=where, fix="downscale the scene's largest textures")


def _too_large(what: str, file: str, where: str) -> TooLarge:
    return TooLarge(
        f"{what}, more than baker decodes (at most {MAX_IMAGE_PIXELS:,}, e.g. 16384×8192: "
        f"{4 * MAX_IMAGE_PIXELS >> 20} MiB as RGBA)",
        file=file, where=where,
        fix="downscale the texture (8192×8192 is plenty for a lightmap bake) and export again")


def _check_png_fits(opened: PILImage.Image, size: int, label: str, file: str, where: str) -> None:
    """Refuse a PNG whose declared pixels cannot be in its ``size`` bytes (see the module)."""
    width, height = opened.size
    bits = {"1": 1, "L": 8, "P": 8, "LA": 16, "RGB": 24, "RGBA": 32, "I;16": 16, "I;16B": 16,
            "I": 32}.get(opened.mode, 64)
    raw = height * (1 + -(-width * bits // 8))  # a filter byte a row
    if raw > _DEFLATE_RATIO * size:
        raise InputError(f"{label} declares {width}×{height} pixels ({raw:,} bytes) but has only "
                         f"{size:,} bytes, which deflate cannot unpack to more than "
                         f"{_DEFLATE_RATIO * size:,}: it is cut short or damaged",
                         file=file, where=where, fix=_FIX)


def _rgba(image: PILImage.Image) -> np.ndarray:
    """A pillow image as (h, w, 4) uint8 RGBA; 16-bit greyscale keeps its high byte."""
    if image.mode.startswith("I"):
        high = (np.asarray(image).astype(np.int64) >> 8).clip(0, 255).astype(np.uint8)
        image = PILImage.fromarray(high, "L")
    return np.array(image.convert("RGBA"), dtype=np.uint8)


def _ktx2(data: bytes, label: str, budget: int, file: str, where: str) -> np.ndarray:
    """A KTX 2 / Basis Universal image's first level transcoded to RGBA8 by opengl-basisu."""
    try:
        import opengl_basisu
    except ImportError:
        raise Undecodable(f"{label} is KTX 2 (Basis Universal), which needs the opengl-basisu "
                          "package, not installed", file=file, where=where,
                          fix=f"{KTX2_EXTRA}, or export the textures as PNG or JPEG") from None
    try:
        texture = opengl_basisu.open(data)
        _check_size((texture.width, texture.height), label, budget, file, where)
        pixels = np.asarray(texture.transcode("rgba8").data, dtype=np.uint8)
    except (opengl_basisu.BasisuError, ValueError) as exc:
        raise InputError(f"cannot decode {label} ({exc})", file=file, where=where,
                         fix=_FIX) from None
    return np.ascontiguousarray(pixels[::-1] if texture.y_flipped else pixels)
