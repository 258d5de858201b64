"""Fuzzing: mutated glTF documents end in a valid output or a clean BakerError (issue 7).

Hypothesis mutates small valid scenes — a JSON field anywhere in the document, an accessor or
bufferView field, bytes of the binary buffer (vertex data, indices, the embedded PNG), the GLB
container itself — or adds a structure that refers to what the file has (``injection``: a
texture on another UV set, an attribute or morph target on any accessor, GPU instances, a light
of extreme size, extension names and extras of any type), and bakes each one through
``baker.bake``. Every run must end in one of two ways:
- a BakerError (InputError, SettingsError, OutputError) with a message and a fix, and no output
  file nor temporary file left behind;
- a bake whose output baker reads back, with finite lightmap texels and error estimate.
Anything else — another exception, a run longer than ``HANG_SECONDS``, a partial file — fails
the test, and hypothesis shrinks it to the smallest mutation that does it.

The CI budget is ``BAKER_FUZZ_EXAMPLES`` mutated inputs (default 200, 5000 with ``BAKER_LONG=1``);
the scenes are tiny and the bake settings minimal (2 rays, 32-texel pages) so that 1000 take
about 30 s. ``BAKER_FUZZ_EXAMPLES=20000 python -m pytest tests/test_fuzz.py`` runs a longer
campaign.
"""

from __future__ import annotations

import copy
import json
import math
import os
import signal
import struct
import tempfile
import time
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import baker
from assets.gltf_builder import GltfBuilder, box, quad
from assets.light_scenes import normal_mapped_floor
from assets.make_scenes import checker, cornell_box, textured_floor
from baker.gltf.container import read_document
from baker.gltf.document import data as document_data
from baker.gltf.load import load
from baker.preview import render
from tests.bakehelp import carried

EXAMPLES = int(os.environ.get("BAKER_FUZZ_EXAMPLES",
                              "5000" if os.environ.get("BAKER_LONG") else "200"))
PREVIEW_EXAMPLES = EXAMPLES // 2
HANG_SECONDS = 20
SCRATCH = "/dev/shm" if os.access("/dev/shm", os.W_OK) else None  # memory: thousands of folders
SETTINGS = baker.Settings(rays=2, page_size=32, padding=1, threads=1, shadow_rays=1,
                          emissive_rays=1, sky_rays=1)


# ------------------------------------------------------------------------------------------------
# the valid documents the mutations start from


def _bases() -> list[tuple[dict, bytes]]:
    """(glTF JSON, binary buffer) of each valid starting scene."""
    out = []
    # 1. a floor quad and a box over it: two meshes, two materials, node TRS.
    b = GltfBuilder()
    floor = b.material("floor", (0.8, 0.8, 0.8))
    red = b.material("red", (0.7, 0.1, 0.1), emissive=(0.2, 0.1, 0.0))
    b.node("floor", b.shape_mesh("floor", quad(1.0, 1.0), material=floor))
    b.node("box", b.shape_mesh("box", box((0.3, 0.3, 0.3)), material=red),
           translation=(0.1, 0.15, 0.0), rotation=(0.0, 0.38268343, 0.0, 0.92387953), scale=(1, 2, 1))
    out.append(b)
    # 2. a textured quad with vertex colours, the same mesh on a parent and a mirrored child.
    b = GltfBuilder()
    textured = b.material("checker", (1, 1, 1), base_color_image=checker(8, 2))
    positions, triangles, normals, uv0 = quad(1.0, 1.0)
    mesh = b.mesh("quad", positions, triangles, normals=normals, uv0=uv0,
                  colors=np.tile([0.9, 0.8, 0.7, 1.0], (len(positions), 1)), material=textured)
    child = b.node("child", mesh, translation=(0, 0.5, 0), scale=(-1, 1, 1))
    b.node("parent", mesh, children=[child])
    out.append(b)
    documents = []
    for b in out:
        document = b.json_data(bin_uri=None)
        documents.append((document, b.binary()))
    return documents


BASES = _bases()


# ------------------------------------------------------------------------------------------------
# mutations

INTERESTING_INTS = [-(2 ** 31), -1, 0, 1, 2, 3, 4, 5, 6, 7, 255, 256, 5120, 5121, 5122, 5123, 5125,
                    5126, 34962, 34963, 2 ** 16, 2 ** 31 - 1, 2 ** 32, 2 ** 53, 10 ** 12]
INTERESTING_FLOATS = [0.0, -0.0, 1e-300, 1e-38, 1e-7, 0.5, 1.0, -1.0, 1e7, 1e30, 1e38, 1e300,
                      -1e300, math.inf, -math.inf, math.nan]
INTERESTING_TEXT = ["", "VEC3", "VEC2", "SCALAR", "MAT4", "BLEND", "MASK", "2.0", "1.0",
                    "data:", "data:application/octet-stream;base64,AAAA", "missing.bin",
                    "../../outside.bin", "http://example.com/x.bin", "%zz", "KHR_draco_mesh_compression"]

values = st.deferred(lambda: st.one_of(
    st.sampled_from(INTERESTING_INTS),
    st.integers(-10, 10 ** 6),
    st.sampled_from(INTERESTING_FLOATS),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(INTERESTING_TEXT),
    st.text(max_size=8),
    st.none(),
    st.booleans(),
    st.lists(st.sampled_from(INTERESTING_FLOATS + [0.0, 1.0]), min_size=0, max_size=17),
    st.builds(dict),  # a new object each draw: one shared {} set inside itself made a cycle
    st.builds(list),
    st.dictionaries(st.sampled_from(["index", "count", "bufferView", "uri", "byteLength"]),
                    st.sampled_from(INTERESTING_INTS), max_size=2),
))


def _like(value):
    """Values of the JSON type of ``value``: a mutation the reader's type check lets through
    (``gltf/document.py`` refuses a value of another type at once), to reach what lies past it."""
    if isinstance(value, bool):
        return st.booleans()
    if isinstance(value, int):
        return st.one_of(st.sampled_from(INTERESTING_INTS), st.integers(-10, 10 ** 6))
    if isinstance(value, float):
        return st.one_of(st.sampled_from(INTERESTING_FLOATS), st.floats())
    if isinstance(value, str):
        return st.one_of(st.sampled_from(INTERESTING_TEXT), st.text(max_size=8))
    return values


def _paths(node, prefix=()) -> list[tuple]:
    """Every path (tuple of keys / indices) into a JSON value, the root excluded."""
    out = []
    if isinstance(node, dict):
        for key, value in node.items():
            out.append(prefix + (key,))
            out += _paths(value, prefix + (key,))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            out.append(prefix + (i,))
            out += _paths(value, prefix + (i,))
    return out


def _parent(document, path):
    node = document
    for key in path[:-1]:
        node = node[key]
    return node


@st.composite
def json_mutation(draw, document: dict, focus: tuple[str, ...] = ()):
    """Change (to any value, or to one of its own JSON type), delete or duplicate one value of
    ``document`` (in place), optionally only under the top-level keys ``focus``."""
    paths = [p for p in _paths(document) if not focus or p[0] in focus] or _paths(document)
    if not paths:  # everything was deleted already
        return None
    path = draw(st.sampled_from(paths))
    parent, key = _parent(document, path), path[-1]
    action = draw(st.sampled_from(["set", "set", "like", "delete", "duplicate"]))
    if action == "delete":
        del parent[key]
    elif action == "duplicate" and isinstance(parent, list):
        parent.insert(key, copy.deepcopy(parent[key]))
    else:
        parent[key] = draw(_like(parent[key]) if action == "like" else values)
    return path


FLOAT_BYTES = [struct.pack("<f", v) for v in (math.nan, math.inf, -math.inf, 3e38, -3e38, 1e-38,
                                              0.0, 1e6, -1e6)]
INT_BYTES = [struct.pack("<I", v) for v in (0, 1, 2 ** 31, 2 ** 32 - 1, 65535, 1000)]


@st.composite
def bytes_mutation(draw, blob: bytearray):
    """Overwrite a few bytes of the binary buffer (in place), often with a special float or int."""
    at = draw(st.integers(0, max(len(blob) - 1, 0)))
    kind = draw(st.sampled_from(["float", "int", "random"]))
    if kind == "random":
        payload = draw(st.binary(min_size=1, max_size=16))
    else:
        at -= at % 4
        payload = draw(st.sampled_from(FLOAT_BYTES if kind == "float" else INT_BYTES))
    blob[at:at + len(payload)] = payload[:max(len(blob) - at, 0)]
    return at


TEXTURE_SLOTS = (("pbrMetallicRoughness", "baseColorTexture"),
                 ("pbrMetallicRoughness", "metallicRoughnessTexture"), (None, "emissiveTexture"),
                 (None, "occlusionTexture"), (None, "normalTexture"))
ATTRIBUTE_NAMES = ("TANGENT", "COLOR_0", "COLOR_1", "JOINTS_0", "WEIGHTS_0", "TEXCOORD_1",
                   "TEXCOORD_2", "TEXCOORD_4", "_CUSTOM")


def _index(draw, items) -> int:
    """An index into ``items`` (a JSON list, or not), or a number past it."""
    count = len(items) if isinstance(items, list) else 0
    return draw(st.one_of(st.integers(0, max(count - 1, 0)), st.sampled_from([count, -1])))


def _each_dict(items) -> list[dict]:
    return [item for item in (items if isinstance(items, list) else []) if isinstance(item, dict)]


@st.composite
def injection(draw, document: dict) -> str:
    """Add a whole valid-looking structure (in place) that refers to what the file has — the
    kinds that found traces the value mutations did not (issue 46's fuzzing of the shared
    scenes): a texture on another UV set, an attribute or morph target on any accessor, GPU
    instances, a light of extreme size, extension names and extras of any JSON type."""
    kind = draw(st.sampled_from(["texcoord", "attribute", "target", "instancing", "light",
                                 "required", "extras"]))
    materials, meshes = _each_dict(document.get("materials")), _each_dict(document.get("meshes"))
    primitives = [p for mesh in meshes for p in _each_dict(mesh.get("primitives"))]
    if kind == "texcoord" and materials:
        outer, slot = draw(st.sampled_from(TEXTURE_SLOTS))
        holder = draw(st.sampled_from(materials))
        if outer is not None:
            holder = holder.setdefault(outer, {}) if isinstance(holder.get(outer, {}), dict) else {}
        holder[slot] = {"index": _index(draw, document.get("textures")),
                        "texCoord": draw(st.sampled_from([1, 2, 3, 31, 32, 1.0, 1.5]))}
    elif kind in ("attribute", "target") and primitives:
        primitive = draw(st.sampled_from(primitives))
        entry = {draw(st.sampled_from(ATTRIBUTE_NAMES + ("POSITION", "NORMAL"))):
                 _index(draw, document.get("accessors"))}
        if kind == "target":
            primitive["targets"] = [entry]
        elif isinstance(primitive.get("attributes"), dict):
            primitive["attributes"].update(entry)
    elif kind == "instancing" and isinstance(document.get("nodes"), list):
        accessors = document.setdefault("accessors", [])
        if isinstance(accessors, list):
            accessors.append({"componentType": 5126, "type": "VEC3",
                              "count": draw(st.sampled_from([1, 2, 1000, 100_000, 10 ** 6]))})
            node = draw(st.sampled_from(_each_dict(document["nodes"]) or [{}]))
            node["extensions"] = {"EXT_mesh_gpu_instancing": {
                "attributes": {"TRANSLATION": len(accessors) - 1}}}
    elif kind == "light" and isinstance(document.get("nodes"), list):
        light = {"type": draw(st.sampled_from(["point", "spot", "directional", "area"])),
                 "intensity": draw(st.sampled_from(INTERESTING_FLOATS)),
                 "spot": {"outerConeAngle": draw(st.sampled_from(INTERESTING_FLOATS))},
                 "extras": {"radius": draw(st.sampled_from(INTERESTING_FLOATS)),
                            "angular_diameter": draw(st.sampled_from(INTERESTING_FLOATS))}}
        document.setdefault("extensions", {})["KHR_lights_punctual"] = {"lights": [light]}
        document["nodes"].append({"extensions": {"KHR_lights_punctual": {"light": 0}},
                                  "translation": [0.0, 1.0, 0.0]})
        scenes = _each_dict(document.get("scenes"))
        if scenes and isinstance(scenes[0].get("nodes"), list):
            scenes[0]["nodes"].append(len(document["nodes"]) - 1)
    elif kind == "required":
        document["extensionsRequired"] = draw(st.lists(st.one_of(
            st.sampled_from(["KHR_lights_punctual", "EXT_mesh_gpu_instancing", "X_unknown"]),
            values), max_size=3))
    elif kind == "extras":
        paths = [p for p in _paths(document) if isinstance(_parent(document, p + ("x",)), dict)]
        holder = _parent(document, draw(st.sampled_from(paths)) + ("x",)) if paths else document
        holder["extras"] = draw(values)
    return kind


def _glb(document: dict, blob: bytes) -> bytes:
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    blob = blob + b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    chunks += struct.pack("<II", len(blob), 0x004E4942) + blob
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


@st.composite
def mutated_files(draw):
    """(file name, {name: bytes}) of one mutated scene: a .glb, or a .gltf with its .bin."""
    document, blob = copy.deepcopy(draw(st.sampled_from(BASES)))
    blob = bytearray(blob)
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["json", "accessor", "accessor", "bytes", "bytes",
                                     "inject", "inject"]))
        if kind == "json":
            draw(json_mutation(document))
        elif kind == "inject":
            draw(injection(document))
        elif kind == "accessor":
            draw(json_mutation(document, ("accessors", "bufferViews")))
        else:
            draw(bytes_mutation(blob))
    container = draw(st.sampled_from(["glb", "glb", "gltf", "glb-bytes"]))
    if container == "gltf":
        buffers = document.get("buffers")
        if isinstance(buffers, list) and buffers and isinstance(buffers[0], dict) and "uri" not in buffers[0]:
            buffers[0]["uri"] = "scene.bin"
        text = json.dumps(document)  # NaN and Infinity as JS literals: not JSON, as some exporters write
        return "scene.gltf", {"scene.gltf": text.encode(), "scene.bin": bytes(blob)}
    data = bytearray(_glb(document, bytes(blob)))
    if container == "glb-bytes":  # damage the container: header, chunk headers, or a cut
        if draw(st.booleans()):
            at = draw(st.sampled_from([0, 4, 8, 12, 16, 20 + len(json.dumps(document))]))
            data[at:at + 4] = draw(st.sampled_from(INT_BYTES))
        else:
            data = data[:draw(st.integers(0, len(data)))]
    return "scene.glb", {"scene.glb": bytes(data)}


# ------------------------------------------------------------------------------------------------
# the property


class Hang(Exception):
    """A run took longer than HANG_SECONDS."""


def _alarm(signum, frame):
    raise Hang(f"a bake ran longer than {HANG_SECONDS} s")


OUTCOMES: dict[str, int] = {}


def bake_ends_cleanly(name: str, files: dict[str, bytes]) -> str:
    """Bake the mutated scene in a fresh folder; return "baked" or the error's class name, and
    fail on anything but a valid output or a clean BakerError with nothing left behind."""
    with tempfile.TemporaryDirectory(prefix="baker-fuzz-", dir=SCRATCH) as folder:
        folder = Path(folder)
        for file, data in files.items():
            (folder / file).write_bytes(data)
        out_dir = folder / "out"
        out_dir.mkdir()
        output = out_dir / ("baked" + Path(name).suffix)
        previous = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, HANG_SECONDS)
        try:
            result = baker.bake(folder / name, output, SETTINGS)
        except baker.BakerError as error:
            assert error.message and error.fix, f"an error without message or fix: {error!r}"
            assert "Traceback" not in str(error)
            left = sorted(p.name for p in out_dir.iterdir())
            assert left == [], f"{type(error).__name__} ({error}) left {left} behind"
            return type(error).__name__
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
        left = sorted(p.name for p in out_dir.iterdir())
        assert output.name in left and not [n for n in left if n.endswith(".tmp")], left
        scene = load(output)  # the output reads back: a whole, valid glTF
        assert all(np.isfinite(p.positions).all() for p in scene.primitives)
        estimate = result.report["rmse_estimate"]
        assert estimate is None or math.isfinite(estimate), f"error estimate {estimate}"
        lightmaps = [m for m in scene.document.materials if carried(m) is not None]
        assert lightmaps or not any(i.baked for i in load(folder / name).instances)
        return "baked"


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(mutated_files())
def test_mutated_gltf_bakes_or_fails_cleanly(case):
    name, files = case
    outcome = bake_ends_cleanly(name, files)
    OUTCOMES[outcome] = OUTCOMES.get(outcome, 0) + 1


def test_the_fuzzer_reaches_both_outcomes_and_its_budget():
    """The run above covered both endings in fair numbers (a fuzzer whose every mutation fails
    in the JSON parser, or none does, would test little), at the rate the CI budget needs."""
    if sum(OUTCOMES.values()) == 0:  # run alone: do a short campaign here
        start = time.perf_counter()
        test_mutated_gltf_bakes_or_fails_cleanly()
        seconds = time.perf_counter() - start
        assert seconds < 60 * EXAMPLES / 2000 + 30, f"{EXAMPLES} inputs took {seconds:.0f} s"
    total = sum(OUTCOMES.values())
    assert total >= min(EXAMPLES, 2000) * 0.9, OUTCOMES
    assert OUTCOMES.get("baked", 0) > 0.1 * total, OUTCOMES
    assert OUTCOMES.get("InputError", 0) > 0.2 * total, OUTCOMES


# ------------------------------------------------------------------------------------------------
# baked files, previewed


_BAKED: list[tuple[dict, bytes]] = []


@st.composite
def reference_mutation(draw, document: dict):
    """Change or delete one field (its texture, UV set, intensity, ...) of a texture reference
    of one of ``document``'s materials (in place): where a baked file's lightmap pages are."""
    references = [reference for material in _each_dict(document.get("materials"))
                  for reference in [material.get("emissiveTexture"),
                                    material.get("occlusionTexture"),
                                    material.get("normalTexture"),
                                    *(material.get("extensions") or {}).values()]
                  if isinstance(reference, dict)]
    if not references:
        return
    reference = draw(st.sampled_from(references))
    key = draw(st.sampled_from(["index", "texCoord", "intensity", "strength", "scale"]))
    if draw(st.integers(0, 3)) == 0:
        reference.pop(key, None)
    else:
        reference[key] = draw(st.one_of(st.sampled_from(WRONG_TYPES).map(copy.deepcopy), values))


WRONG_TYPES = ["x", [1], {"index": 0}, 0.5, -1, 99, 2 ** 40, None, True, math.nan, math.inf]
"""Values of another type, or out of range, for a texture reference's fields."""


def baked_bases() -> list[tuple[dict, bytes]]:
    """(glTF JSON, binary buffer) of small bakes of each carrier: the Cornell room with the moz
    and the emissive carrier, a textured floor with the occlusion carrier, a normal-mapped floor
    with directional pages; made once, on first use."""
    if not _BAKED:
        cases = ((cornell_box, dict(carrier="moz")), (cornell_box, {}),
                 (textured_floor, dict(carrier="occlusion")),
                 (normal_mapped_floor, dict(directional=True)))
        with tempfile.TemporaryDirectory(prefix="baker-fuzz-", dir=SCRATCH) as folder:
            for k, (make, options) in enumerate(cases):
                out = Path(folder) / f"baked{k}.glb"
                baker.bake(make().save(Path(folder) / f"scene{k}.glb"), out,
                           baker.Settings(rays=2, page_size=32, padding=1, threads=1, **options),
                           state=False)
                document = read_document(out)
                _BAKED.append((document_data(document), document.binary_blob()))
    return _BAKED


@settings(max_examples=PREVIEW_EXAMPLES, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.data())
def test_a_mutated_baked_file_previews_or_fails_cleanly(data):
    """``baker preview`` (and ``baker view``, which renders the same way) of a baked file with
    a field of one of its materials' texture references (where the lightmap pages are named)
    changed or deleted, and up to two more values of its JSON changed, deleted or duplicated:
    a picture, or a BakerError with a message and a fix. Its lightmap references were read
    unchecked (52 internal errors in 800 such files before they were checked)."""
    bases = baked_bases()
    document, blob = copy.deepcopy(bases[data.draw(st.integers(0, len(bases) - 1))])
    data.draw(reference_mutation(document))
    for _ in range(data.draw(st.integers(0, 2))):
        focus = data.draw(st.sampled_from([("materials",), ("materials", "textures", "images"),
                                           ("meshes", "nodes", "asset"), ()]))
        data.draw(json_mutation(document, focus))
    mode = data.draw(st.sampled_from(["lit", "lightmap", "checker", "unlit"]))
    with tempfile.TemporaryDirectory(prefix="baker-fuzz-", dir=SCRATCH) as folder:
        path = Path(folder) / "baked.glb"
        path.write_bytes(_glb(document, bytes(blob)))
        previous = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, HANG_SECONDS)
        try:
            picture = render(load(path), mode, (16, 12))
        except baker.BakerError as error:
            assert error.message and error.fix, f"an error without message or fix: {error!r}"
            return
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
    assert picture.rgb.shape == (12, 16, 3)
