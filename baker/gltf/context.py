"""What every step of reading a glTF file shares: the reading's ``Context`` (the document,
its buffers, the things left out) and the errors they raise, each naming the file and the glTF
JSON path (``invalid``, ``checked_item``, ``finite``, ``referred``, ``schema``)."""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Iterator, Sequence

import numpy as np

from baker.errors import InputError
from baker.gltf import images, objects
from baker.gltf.files import SceneFolder
from baker.gltf.scene import Skipped


@dataclass
class Context:
    """What every reading step needs: the document, its buffers as bytes, where the file lives,
    and the list of things left out so far."""

    document: objects.GLTF2
    buffers: list[bytes]
    file: str
    folder: SceneFolder | None  # None once the load is done (``image_pixels``)
    skipped: list[Skipped] = field(default_factory=list)
    decoded: dict[int, np.ndarray] = field(default_factory=dict)  # image index → (h, w, 4) uint8
    image_files: dict[int, bytes] = field(default_factory=dict)  # image index → its file's bytes
    headers: dict[int, images.Header] = field(default_factory=dict)  # image index → its header

    def skip(self, where: str, reason: str) -> None:
        """Record something left out, once."""
        entry = Skipped(where=where, reason=reason)
        if entry not in self.skipped:
            self.skipped.append(entry)


MAX_ALBEDO = 1e3
"""The largest colour factor or vertex colour baker bakes as given (the spec's are at most 1;
above 1 a surface reflects more than it receives, which the obscurance's series bounds:
``light.ambient``); above it, or below 0, one is clamped with a warning (10³⁰⁸ made a page of
infinite intensity)."""

REEXPORT = "re-export the asset from your DCC tool; the Khronos glTF Validator shows what is wrong"


def invalid(message: str, file: str, where: str) -> InputError:
    """An InputError for data that breaks the glTF spec; the fix is always to export again."""
    return InputError(message, file=file, where=where, fix=REEXPORT)


def attributes_of(primitive: Any) -> dict[str, Any]:
    """A mesh primitive's attributes as {name: accessor index}, those the file leaves out (None)
    dropped (a primitive's are an ``objects.Attributes``, a morph target's a dict; the
    container refused any other JSON: ``container._check_primitives``)."""
    raw = primitive.attributes
    if raw is None:
        return {}
    return {k: v for k, v in (raw if isinstance(raw, dict) else vars(raw)).items()
            if v is not None}


def or_default(value: Any, default: Any) -> Any:
    """``value``, or ``default`` when the file leaves it out (its field is None)."""
    return default if value is None else value


def checked_item(items: Sequence, index: Any, kind: str, file: str, referrer: str) -> Any:
    """``items[index]``, or an InputError at ``referrer`` when ``index`` is not a valid index."""
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(items):
        raise invalid(f"refers to {kind}[{index}] but the file has {len(items)} {kind}", file,
                      referrer)
    return items[index]


def finite(ctx: Context, value: Any, length: int, where: str) -> np.ndarray:
    """``value`` as a (length,) float64 array of finite numbers, or an InputError."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        array = None
    if array is None or array.shape != (length,) or not np.isfinite(array).all():
        raise invalid(f"expected {length} finite numbers, found {value!r}", ctx.file, where)
    return array


@contextmanager
def referred(referrer: str) -> Iterator[None]:
    """Name the object that refers to the faulty one too: an error at ``accessors[4]`` read for
    POSITION is reported at ``meshes[1].primitives[0].attributes.POSITION → accessors[4]``."""
    try:
        yield
    except InputError as error:
        if not error.where.startswith(referrer):
            error.where = f"{referrer} → {error.where}" if error.where else referrer
        raise


@contextmanager
def schema(file: str, where: str) -> Iterator[None]:
    """Turn the errors that malformed JSON values provoke (a string where a number belongs, …)
    into an InputError at ``where``."""
    try:
        yield
    except (TypeError, ValueError, AttributeError, KeyError, IndexError) as exc:
        message = f"does not follow the glTF 2.0 schema ({type(exc).__name__}: {exc})"
        raise invalid(message, file, where) from exc
