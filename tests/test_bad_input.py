"""Bad input never costs the user data (issue 7).

Every case runs the command line as a user does — in-process through ``baker.cli.main.main`` (so the
exit code and stderr are checked exactly), and a few as a real ``baker bake`` subprocess — and
checks three things:
- the exit code (1 for bad input, settings or output; 130 when interrupted);
- the message: one or two lines, ``baker: error: <file>: <glTF path>: <what> / fix: <what to do>``,
  never a traceback;
- nothing the user had changed and nothing new appeared: a previous output stays byte for byte,
  no temporary file is left (the whole folder is compared before and after).
"""

from __future__ import annotations

import ctypes
import importlib
import json
import os
import resource
import signal
import struct
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

import numpy as np
import pygltflib
import pytest

import baker
from assets.gltf_builder import GltfBuilder, box, quad
from assets.make_scenes import checker, cornell_box
from baker.gltf.context import MAX_ALBEDO
from baker.gltf.load import load
from baker.run.parallel import run_chunks
from baker.cli.main import main
from tests.bakehelp import carried

ROOT = Path(__file__).resolve().parents[1]
API = importlib.import_module("baker.api")  # the modules (``baker.bake`` is the function)
FULL = importlib.import_module("baker.pipeline.full")
PREVIOUS = b"the previous bake: must survive every failure\n"
FAST = ["--rays", "2", "--page-size", "64", "--quiet"]


# ------------------------------------------------------------------------------------------------
# scenes and helpers


def small_scene(textured: bool = False) -> GltfBuilder:
    """A 2 m floor with a 0.5 m box on it: bakes in a fraction of a second."""
    b = GltfBuilder()
    image = checker(16, 4) if textured else None
    floor_mat = b.material("floor", (0.8, 0.8, 0.8), base_color_image=image)
    box_mat = b.material("box", (0.6, 0.3, 0.2))
    b.node("floor", b.shape_mesh("floor", quad(2.0, 2.0), material=floor_mat))
    b.node("box", b.shape_mesh("box", box((0.5, 0.5, 0.5)), material=box_mat), translation=(0, 0.25, 0))
    return b


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden temporaries included) with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def bake_cli(capsys, *argv: str) -> tuple[int, str, str]:
    """Run ``baker`` in-process; return (exit code, stdout, stderr)."""
    code = main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def assert_one_clean_message(err: str, *parts: str) -> None:
    """``err`` is baker's one- or two-line error naming every one of ``parts`` and a fix."""
    assert err.startswith("baker: error: "), err
    assert "Traceback" not in err and "internal error" not in err, err
    lines = err.strip().splitlines()
    assert 1 <= len(lines) <= 2, err
    assert lines[-1].strip().startswith("fix: ") and len(lines[-1].strip()) > 10, err
    for part in parts:
        assert part in err, f"{part!r} not in {err!r}"


def refuses(tmp_path, capsys, source: Path, *parts: str, args=(), output: Path | None = None) -> str:
    """Bake ``source`` over an existing output; check exit 1, the message and that no file changed."""
    output = output or tmp_path / "out" / "baked.glb"
    output.parent.mkdir(exist_ok=True)
    if output != source:
        output.write_bytes(PREVIOUS)
    before = snapshot(tmp_path)
    code, out, err = bake_cli(capsys, "bake", str(source), "-o", str(output), *FAST, *args)
    assert code == 1, err
    assert out == ""
    assert_one_clean_message(err, *parts)
    assert snapshot(tmp_path) == before
    return err


def gltf_pair(tmp_path, builder=None, name="scene.gltf") -> tuple[Path, dict, Path]:
    """Save a scene as .gltf + .bin; return the .gltf path, its JSON and the .bin path."""
    path = (builder or small_scene()).save(tmp_path / name)
    document = json.loads(path.read_text())
    return path, document, path.with_name(document["buffers"][0]["uri"])


def rewrite(path: Path, document: dict) -> Path:
    path.write_text(json.dumps(document))
    return path


def poke_bin(bin_path: Path, document: dict, accessor: int, element: int, value: bytes) -> None:
    """Overwrite element ``element`` of ``accessors[accessor]`` in the .bin with ``value``."""
    acc = document["accessors"][accessor]
    view = document["bufferViews"][acc["bufferView"]]
    size = {5126: 4, 5125: 4}[acc["componentType"]] * {"SCALAR": 1, "VEC3": 3}[acc["type"]]
    data = bytearray(bin_path.read_bytes())
    at = view.get("byteOffset", 0) + acc.get("byteOffset", 0) + element * size
    data[at:at + len(value)] = value
    bin_path.write_bytes(bytes(data))


def png_chunk(kind: bytes, payload: bytes) -> bytes:
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))


def huge_png(width: int, height: int) -> bytes:
    """A tiny PNG file whose header claims ``width`` × ``height`` RGBA pixels."""
    header = struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0)
    data = zlib.compress(b"\0" * 64)
    return (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", header) + png_chunk(b"IDAT", data)
            + png_chunk(b"IEND", b""))


# ------------------------------------------------------------------------------------------------
# the file


def test_not_a_gltf_file(tmp_path, capsys):
    source = tmp_path / "holiday.glb"
    source.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4)
    refuses(tmp_path, capsys, source, str(source), "not a glTF", ".gltf or .glb")


def test_debug_raises_the_typed_error_with_its_traceback(tmp_path):
    """``--debug`` lets the library's typed error through (the traceback), with the same
    message: one exception family, rendered as one line only without it."""
    source = tmp_path / "holiday.glb"
    source.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
    with pytest.raises(baker.InputError, match="not a glTF file"):
        main(["bake", str(source), "-o", str(tmp_path / "out.glb"), "--debug", *FAST])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["holiday.glb"]


@pytest.mark.parametrize("carrier", ["emissive", "moz"])
def test_a_bake_given_again_as_input_is_refused_naming_it(tmp_path, capsys, carrier):
    """A file baker wrote (asset.extras.baker), e.g. the scene after ``--overwrite`` replaced
    it with its bake, baked again: exit 1 naming asset.extras.baker and the carrier, the fix
    saying to bake its source (before: under the emissive carrier "nothing baked: black base
    colour", exit 4; under moz, copies of the copies). The library refuses it too, in memory.
    With asset.extras.baker removed, the file is baked as it is: the moz copies keep their
    base colours and bake; the emissive ones are black, and nothing is baked (exit 4)."""
    source = small_scene().save(tmp_path / "scene.glb")
    baked = tmp_path / "scene_baked.glb"
    assert main(["bake", str(source), "-o", str(baked), "--carrier", carrier, "--no-state",
                 *FAST]) == 0
    capsys.readouterr()
    err = refuses(tmp_path, capsys, baked, "asset.extras.baker", f"carrier {carrier}",
                  "bake the scene it was made from")
    assert str(baked) in err
    with pytest.raises(baker.InputError, match="a bake baker wrote"):
        baker.compute(baker.load(baked), baker.Settings(rays=2, page_size=32))
    document = pygltflib.GLTF2().load(str(baked))
    del document.asset.extras["baker"]
    document.save(str(baked))
    assert main(["bake", str(baked), "-o", str(tmp_path / "again.glb"), "--no-state",
                 *FAST]) == (0 if carrier == "moz" else 4)


def test_missing_input_file(tmp_path, capsys):
    refuses(tmp_path, capsys, tmp_path / "nowhere.glb", "nowhere.glb", "not found")


@pytest.mark.parametrize("cut", [5, 30, 1000])
def test_truncated_glb(tmp_path, capsys, cut):
    source = small_scene().save(tmp_path / "scene.glb")
    data = source.read_bytes()
    source.write_bytes(data[:cut] if cut < 100 else data[:-cut])
    refuses(tmp_path, capsys, source, str(source), "truncated GLB", "GLB", "copy or export it again")


def test_malformed_json(tmp_path, capsys):
    source = tmp_path / "scene.gltf"
    source.write_text('{\n  "asset": {"version": "2.0"},\n  "nodes": [ {"mesh": 0},, ]\n}\n')
    refuses(tmp_path, capsys, source, str(source), "not valid JSON", "line 3", "fix the JSON at that line")


def _light_intensity(document: dict, value) -> None:
    document.setdefault("extensions", {})["KHR_lights_punctual"] = {
        "lights": [{"type": "point", "intensity": value}]}
    document.setdefault("extensionsUsed", []).append("KHR_lights_punctual")


@pytest.mark.parametrize("token, where, put", [
    # kept, the output's JSON could not be written
    ("NaN", "meshes[0].weights[0]", lambda d, v: d["meshes"][0].update(weights=[v])),
    ("-Infinity", "nodes[1].translation[0]", lambda d, v: d["nodes"][1].update(translation=[v, 0, 0])),
    ("1e400", "nodes[1].translation[0]", lambda d, v: d["nodes"][1].update(translation=[v, 0, 0])),
    ("9" * 350, "extensions.KHR_lights_punctual.lights[0].intensity", _light_intensity),
])
def test_a_number_past_float64_is_refused_naming_where(tmp_path, capsys, token, where, put):
    """NaN and Infinity (which Python's JSON parser takes), a float literal past float64's
    range (valid JSON), an integer of 350 digits: exit 1 naming the number's place, nothing
    written (a NaN morph weight ended in an internal error when the output was written, a long
    integer as a light's intensity when it was read)."""
    source, document, _ = gltf_pair(tmp_path)
    put(document, "TOKEN")
    source.write_text(json.dumps(document).replace('"TOKEN"', token))
    refuses(tmp_path, capsys, source, str(source), where, "not a finite float64",
            "write a finite number there")


@pytest.mark.parametrize("version", ["1.0", "3.0", None])
def test_wrong_gltf_version(tmp_path, capsys, version):
    source, document, _ = gltf_pair(tmp_path)
    document["asset"]["version"] = version
    refuses(tmp_path, capsys, rewrite(source, document), str(source), "asset.version", "glTF 2")


def test_missing_bin(tmp_path, capsys):
    source, _, bin_path = gltf_pair(tmp_path)
    bin_path.unlink()
    refuses(tmp_path, capsys, source, str(source), "buffers[0].uri", "not found", "beside the .gltf")


def test_short_bin(tmp_path, capsys):
    source, _, bin_path = gltf_pair(tmp_path)
    bin_path.write_bytes(bin_path.read_bytes()[:100])
    refuses(tmp_path, capsys, source, str(source), "buffers[0]", "byteLength", "export the asset again")


@pytest.mark.parametrize("uri", ["data:application/octet-stream;base64,@@not base64@@",
                                 "data:application/octet-stream;base64"])
def test_bad_data_uri(tmp_path, capsys, uri):
    source, document, _ = gltf_pair(tmp_path)
    document["buffers"][0]["uri"] = uri
    refuses(tmp_path, capsys, rewrite(source, document), str(source), "buffers[0].uri", "data URI")


def test_accessor_out_of_bounds_names_the_attribute_and_the_accessor(tmp_path, capsys):
    source, document, _ = gltf_pair(tmp_path)
    position = document["meshes"][1]["primitives"][0]["attributes"]["POSITION"]
    document["accessors"][position]["count"] += 1000
    refuses(tmp_path, capsys, rewrite(source, document), str(source),
            "meshes[1].primitives[0].attributes.POSITION", f"accessors[{position}]",
            "export the asset again")


@pytest.mark.parametrize("where", ["attributes._WIND", "targets[0].POSITION"])
def test_an_attribute_shorter_than_position_is_refused_naming_it(tmp_path, capsys, where):
    """A custom attribute or a morph target's POSITION of one element where POSITION has four
    (glTF forbids it): refused at load, naming it. The writer, which copies every vertex's row
    of each attribute, ended in an internal error."""
    source, document, _ = gltf_pair(tmp_path)
    primitive = document["meshes"][0]["primitives"][0]
    position = primitive["attributes"]["POSITION"]
    document["accessors"].append(dict(document["accessors"][position], count=1))
    short = len(document["accessors"]) - 1
    if where.startswith("targets"):
        primitive["targets"] = [{"POSITION": short}]
    else:
        primitive["attributes"]["_WIND"] = short
    refuses(tmp_path, capsys, rewrite(source, document), f"meshes[0].primitives[0].{where}",
            f"accessors[{short}] has a count of 1, POSITION 4")


def test_a_morph_target_position_with_nan_is_refused_naming_its_accessor(tmp_path, capsys):
    """A morph target whose POSITION holds a NaN: its min and max cannot be written (the JSON
    writer raised ValueError); refused, naming the accessor, no output written."""
    source, document, bin_path = gltf_pair(tmp_path)
    primitive = document["meshes"][0]["primitives"][0]
    data = bin_path.read_bytes()
    shifts = np.zeros((4, 3), np.float32)
    shifts[2, 1] = np.nan
    document["bufferViews"].append({"buffer": 0, "byteOffset": len(data), "byteLength": 48})
    document["buffers"][0]["byteLength"] = len(data) + 48
    bin_path.write_bytes(data + shifts.tobytes())
    document["accessors"].append({"bufferView": len(document["bufferViews"]) - 1, "count": 4,
                                  "componentType": 5126, "type": "VEC3",
                                  "min": [0, 0, 0], "max": [0, 0, 0]})
    primitive["targets"] = [{"POSITION": len(document["accessors"]) - 1}]
    refuses(tmp_path, capsys, rewrite(source, document),
            f"accessors[{len(document['accessors']) - 1}]", "NaN or infinite")


def test_an_extension_name_that_is_not_a_string_is_refused(tmp_path, capsys):
    source, document, _ = gltf_pair(tmp_path)
    document["extensionsRequired"] = [["KHR_lights_punctual"]]
    refuses(tmp_path, capsys, rewrite(source, document), "extensionsRequired[0]",
            "is list, not an extension's name")


def test_a_texture_reading_a_uv_set_a_primitive_lacks_reads_zeros(tmp_path):
    """A metallicRoughnessTexture, transmissionTexture or occlusionTexture on TEXCOORD_1 of a
    floor that has TEXCOORD_0 only: baked, and the warning counted, as the same floor with a
    TEXCOORD_1 of zeros (what a viewer reads for an attribute a primitive lacks) bakes it.
    Reading them ended in an IndexError."""
    source, document, bin_path = gltf_pair(tmp_path, small_scene(textured=True))
    floor = document["meshes"][0]["primitives"][0]
    material = document["materials"][floor["material"]]
    material["pbrMetallicRoughness"]["metallicRoughnessTexture"] = {"index": 0, "texCoord": 1}
    material["occlusionTexture"] = {"index": 0, "texCoord": 1}
    material["extensions"] = {"KHR_materials_transmission": {
        "transmissionFactor": 0.5, "transmissionTexture": {"index": 0, "texCoord": 1}}}
    document["extensionsUsed"] = ["KHR_materials_transmission"]
    lacking = rewrite(tmp_path / "lacking.gltf", document)
    data = bin_path.read_bytes()
    count = document["accessors"][floor["attributes"]["POSITION"]]["count"]
    document["bufferViews"].append({"buffer": 0, "byteOffset": len(data),
                                    "byteLength": 8 * count})
    document["buffers"][0]["byteLength"] = len(data) + 8 * count
    document["accessors"].append({"bufferView": len(document["bufferViews"]) - 1,
                                  "count": count, "componentType": 5126, "type": "VEC2"})
    floor["attributes"]["TEXCOORD_1"] = len(document["accessors"]) - 1
    zeros = tmp_path / "zeros"
    zeros.mkdir()
    (zeros / bin_path.name).write_bytes(data + bytes(8 * count))
    pages = {}
    for name, scene in (("lacking", lacking), ("zeros", rewrite(zeros / "scene.gltf", document))):
        result = baker.bake(scene, tmp_path / f"{name}.glb", baker.Settings(rays=2, page_size=64),
                            lightmaps_dir=tmp_path / f"{name}_pages", lightmaps_format="exr")
        pages[name] = [f.read_bytes() for f in sorted((tmp_path / f"{name}_pages").iterdir())]
        warned = [text for text in result.report["warnings"] if "UV set" in text]
        assert len(warned) == (name == "lacking"), result.report["warnings"]
    assert pages["lacking"] == pages["zeros"] and pages["lacking"]


@pytest.mark.parametrize("empty", [True, False])
def test_a_primitive_with_empty_attributes_stays_readable_in_the_output(tmp_path, empty):
    """A primitive with ``attributes: {}``, or none at all (nothing to place: left out, counted)
    keeps the required key in the output, which reads back; the output once dropped it as an
    empty property, and reading it failed inside pygltflib. Without the key, reading the
    file once ended in an internal error (the fuzzer's find)."""
    source, document, _ = gltf_pair(tmp_path)
    primitive = document["meshes"][1]["primitives"][0]
    if empty:
        primitive["attributes"] = {}
    else:
        del primitive["attributes"]
    result = baker.bake(rewrite(source, document), tmp_path / "out.glb",
                        baker.Settings(rays=2, page_size=64))
    assert result.report["warnings"].get("no POSITION attribute: nothing to place") == 1
    written = load(tmp_path / "out.glb")
    assert written.document.meshes[1].primitives[0].attributes is not None


def test_gpu_instances_past_the_placed_triangles_budget_are_refused_at_once(tmp_path, capsys):
    """A 4 kB file whose box is placed 100,000 times by EXT_mesh_gpu_instancing (translations
    without a bufferView: zeros), 1.2 M triangles: past what an input of its size may place
    (``budget.check_placed``), refused before any instance is made, naming the node. 300,000
    instances of a ball (384 M triangles) were killed at 21 GB."""
    source, document, _ = gltf_pair(tmp_path)
    document["accessors"].append({"componentType": 5126, "count": 100_000, "type": "VEC3"})
    document["nodes"][1]["extensions"] = {"EXT_mesh_gpu_instancing": {
        "attributes": {"TRANSLATION": len(document["accessors"]) - 1}}}
    document["extensionsUsed"] = ["EXT_mesh_gpu_instancing"]
    err = refuses(tmp_path, capsys, rewrite(source, document), "nodes[1]",
                  "the nodes place 1,200,002 triangles in all", "places the most, 1,200,000",
                  "place fewer instances")
    size = source.stat().st_size + source.with_suffix(".bin").stat().st_size
    assert f"an input of {size:,} bytes" in err  # the scene file counted with its buffer


def test_gpu_instances_at_one_place_bake_as_one_surface(tmp_path):
    """A 4 kB file whose floor is placed 100,000 times at the origin by EXT_mesh_gpu_instancing
    (translations without a bufferView: zeros), 200,002 triangles, within the budget: every
    ray that reached the floor tested every copy, and the bake ran past 7 minutes (the
    fuzzer's find). The copies are traced once (``geometry/repeats.py``) and the instances
    placed a primitive at a time: it bakes (here under a 60 s guard, in about 2 s)."""
    source, document, _ = gltf_pair(tmp_path)
    document["accessors"].append({"componentType": 5126, "count": 100_000, "type": "VEC3"})
    document["nodes"][0]["extensions"] = {"EXT_mesh_gpu_instancing": {
        "attributes": {"TRANSLATION": len(document["accessors"]) - 1}}}
    document["extensionsUsed"] = ["EXT_mesh_gpu_instancing"]

    def hang(signum, frame):
        raise TimeoutError("the bake of 100,000 copies ran past 60 s")

    previous = signal.signal(signal.SIGALRM, hang)
    signal.setitimer(signal.ITIMER_REAL, 60)
    try:
        result = baker.bake(rewrite(source, document), tmp_path / "out.glb",
                            baker.Settings(rays=2, page_size=32, shadow_rays=1))
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert (tmp_path / "out.glb").exists()
    assert result.report["plan"]["left_out"] == [{  # one entry for the node's 100,000
        "where": "nodes[0] (floor) meshes[0].primitives[0]",
        "reason": "GPU-instanced (EXT_mesh_gpu_instancing): occluder only", "count": 100_000}]


def test_a_scene_file_reached_through_a_link_bakes_as_the_file(tmp_path):
    """``baker bake link.glb`` where link.glb is a symbolic link to a scene elsewhere: the same
    bytes as baking the scene itself (only ``baker hook`` reads its scene file as contained;
    a bake read every scene file so, its budget passed where the flag belongs)."""
    real = small_scene().save(tmp_path / "assets" / "room.glb")
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "link.glb").symlink_to(real)
    settings = baker.Settings(rays=2, page_size=64)
    baker.bake(real, tmp_path / "real_baked.glb", settings, state=False)
    baker.bake(tmp_path / "work" / "link.glb", tmp_path / "link_baked.glb", settings, state=False)
    assert (tmp_path / "link_baked.glb").read_bytes() == (tmp_path / "real_baked.glb").read_bytes()


@pytest.mark.parametrize("kind", ["VEC2", "SCALAR"])
def test_a_uv_set_after_a_gap_is_checked_as_the_output_will_read_it(tmp_path, capsys, kind):
    """TEXCOORD_2 without TEXCOORD_1 is left out of the bake, but the output fills the gap with
    the lightmap's set, and reading the output then reads TEXCOORD_2 too: a VEC2 bakes to an
    output that reads back; a SCALAR is refused at load, naming it (it made an output baker
    could not read again)."""
    source, document, _ = gltf_pair(tmp_path)
    floor = document["meshes"][0]["primitives"][0]
    uv = document["accessors"][floor["attributes"]["TEXCOORD_0"]]
    document["accessors"].append(dict(uv, type=kind, count=uv["count"] * (2 if kind == "SCALAR"
                                                                          else 1)))
    floor["attributes"]["TEXCOORD_2"] = len(document["accessors"]) - 1
    rewrite(source, document)
    if kind == "SCALAR":
        refuses(tmp_path, capsys, source, "meshes[0].primitives[0].attributes.TEXCOORD_2",
                "1 components per vertex")
        return
    baker.bake(source, tmp_path / "out.glb", baker.Settings(rays=2, page_size=64))
    assert len(load(tmp_path / "out.glb").primitives[0].texcoords) == 3  # 0, the lightmap's, 2


def test_accessor_with_an_absurd_count_is_refused_without_allocating(tmp_path, capsys):
    source, document, _ = gltf_pair(tmp_path)
    position = document["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
    del document["accessors"][position]["bufferView"]  # all zeros, count elements
    document["accessors"][position]["count"] = 10 ** 13
    refuses(tmp_path, capsys, rewrite(source, document), str(source),
            "meshes[0].primitives[0].attributes.POSITION", f"accessors[{position}]")


def test_index_out_of_range(tmp_path, capsys):
    source, document, bin_path = gltf_pair(tmp_path)
    indices = document["meshes"][1]["primitives"][0]["indices"]
    poke_bin(bin_path, document, indices, 7, struct.pack("<I", 4_000_000))
    refuses(tmp_path, capsys, source, str(source), "meshes[1].primitives[0].indices",
            "index 4000000", "out of range")


@pytest.mark.parametrize("value", [struct.pack("<f", float("nan")), struct.pack("<f", np.inf),
                                   struct.pack("<f", -np.inf), struct.pack("<I", 0x7F800001)],
                         ids=["NaN", "inf", "-inf", "signalling NaN"])
def test_nan_or_inf_in_positions(tmp_path, capsys, value):
    """Refused naming the vertex, and with no warning of numpy's before the message (a
    signalling NaN's cast to float64 gave one)."""
    import warnings

    source, document, bin_path = gltf_pair(tmp_path)
    position = document["meshes"][1]["primitives"][0]["attributes"]["POSITION"]
    zero = struct.pack("<f", 0.0)
    poke_bin(bin_path, document, position, 5, zero + value + zero)
    with warnings.catch_warnings(record=True) as warned:
        warnings.simplefilter("always")
        refuses(tmp_path, capsys, source, str(source),
                "meshes[1].primitives[0].attributes.POSITION", "NaN or infinite", "vertex 5",
                "Clean Up")
    assert [str(w.message) for w in warned] == []


def test_unsupported_required_extension(tmp_path, capsys):
    source, document, _ = gltf_pair(tmp_path)
    document["extensionsUsed"] = document["extensionsRequired"] = ["ACME_materials_glitter"]
    refuses(tmp_path, capsys, rewrite(source, document), str(source), "extensionsRequired",
            "ACME_materials_glitter: a material extension", "re-export without")


def test_undecodable_texture_names_the_image_and_the_material(tmp_path, capsys):
    source, document, bin_path = gltf_pair(tmp_path, small_scene(textured=True))
    view = document["bufferViews"][document["images"][0]["bufferView"]]
    data = bytearray(bin_path.read_bytes())
    start = view.get("byteOffset", 0)
    data[start + 16:start + view["byteLength"]] = b"\x17" * (view["byteLength"] - 16)
    bin_path.write_bytes(bytes(data))
    refuses(tmp_path, capsys, source, str(source), "images[0]",
            "materials[0].pbrMetallicRoughness.baseColorTexture", "cannot decode",
            "re-save the image")


@pytest.mark.parametrize("side, says", [(60_000, "3,600,000,000 pixels"),
                                        (12_000, "12000×12000 = 144,000,000 pixels")])
def test_image_far_larger_than_memory_allows(tmp_path, capsys, side, says):
    """A PNG whose header claims side² pixels (13 GiB of RGBA at 60 000²): refused from the
    header alone, before a byte of pixels is decoded."""
    source, document, _ = gltf_pair(tmp_path, small_scene(textured=True))
    (tmp_path / "huge.png").write_bytes(huge_png(side, side))
    document["images"][0] = {"uri": "huge.png"}
    start = time.perf_counter()
    refuses(tmp_path, capsys, rewrite(source, document), str(source),
            "materials[0].pbrMetallicRoughness.baseColorTexture → images[0]", says,
            "more than baker decodes", "downscale")
    assert time.perf_counter() - start < 5


# ------------------------------------------------------------------------------------------------
# settings


@pytest.mark.parametrize("option, value, name", [
    ("--d-max", "0", "d_max"), ("--d-max", "-2", "d_max"), ("--d-max", "nan", "d_max"),
    ("--rays", "0", "rays"), ("--rays", "-16", "rays"),
    ("--texel-density", "0", "texel_density"), ("--texel-density", "-4", "texel_density"),
    ("--texel-density", "inf", "texel_density"),
    # past what the bake can hold: each once an internal error (an allocation no memory holds,
    # an integer no C long holds, a float overflow), now refused before any work
    ("--rays", "100000000000", "rays"), ("--shadow-rays", "100000", "shadow_rays"),
    ("--seed", "9" * 23, "seed"), ("--d-max", "1e300", "d_max"),
    ("--texel-density", "1e300", "texel density"), ("--sky", "1e300,1,1", "sky"),
    ("--sky-intensity", "1e40", "sky_intensity"),
    # padding that leaves a 64-texel page no room for a chart: once "at texel density -682.57
    # a triangle is -1.93e+03 texels long"
    ("--padding", "31", "leaves no room for a chart"),
])
def test_bad_settings(tmp_path, capsys, option, value, name):
    source = small_scene().save(tmp_path / "scene.glb")
    refuses(tmp_path, capsys, source, name, option, args=(option, value))


def test_a_page_too_small_for_the_density_says_what_would_fit(tmp_path, capsys):
    """The 2 m floor needs ~200 texels a side at 100 texels/m: a 64-texel page cannot hold it.
    xatlas would silently shrink the chart; baker refuses and says which density or page fits."""
    source = small_scene().save(tmp_path / "scene.glb")
    err = refuses(tmp_path, capsys, source, str(source), "--texel-density", "--page-size",
                  args=("--texel-density", "100"))
    fits = float(err.split("--texel-density ")[1].split()[0])
    page = int(err.split("--page-size ")[1].split()[0])
    assert 15 < fits < 32 and page >= 200
    # Both suggestions work: the bake at either one succeeds and keeps the density asked for.
    for args in (["--texel-density", f"{fits}"], ["--texel-density", "100", "--page-size", f"{page}"]):
        out = tmp_path / f"ok{len(args)}.glb"
        code, _, err = bake_cli(capsys, "bake", str(source), "-o", str(out), "--rays", "2",
                                "--page-size", args[3] if len(args) > 2 else "64", "--quiet", *args[:2])
        assert code == 0, err


def test_a_density_no_memory_could_hold_is_refused_at_once(tmp_path, capsys):
    """10⁵ texels/m on ~6 m² is 6·10¹⁰ texels: refused before xatlas runs, with what fits."""
    source = small_scene().save(tmp_path / "scene.glb")
    start = time.perf_counter()
    err = refuses(tmp_path, capsys, source, str(source), "--texel-density", "texels",
                  args=("--texel-density", "1e5"))
    assert time.perf_counter() - start < 5
    fits = float(err.split("--texel-density ")[1].split()[0])
    assert 100 < fits < 10_000


def test_default_density_shrinks_to_what_fits_a_long_wall(tmp_path, capsys):
    """No density given: a 100 m × 1 m wall cannot fill half a 64-texel page at one density in
    one chart, so the derived density drops until the wall fits; the report says which."""
    b = GltfBuilder()
    b.node("wall", b.shape_mesh("wall", quad(100.0, 1.0), material=b.material("w")))
    source = b.save(tmp_path / "wall.glb")
    result = baker.bake(source, tmp_path / "wall_baked.glb", baker.Settings(rays=2, page_size=64))
    assert 0.4 < result.settings.texel_density <= 0.62  # ≤ 62 texels / 100 m
    assert result.report["atlas"]["texel_density"] == result.settings.texel_density


# ------------------------------------------------------------------------------------------------
# the output


def test_output_and_report_in_missing_folders_are_made(tmp_path, capsys):
    """``-o out/level.gltf`` when out/ does not exist (the README's line): the folders of the
    output and the report are made, as ``mkdir -p`` would, and the bake writes into them."""
    source = small_scene().save(tmp_path / "scene.glb")
    output = tmp_path / "no" / "such" / "folder" / "baked.gltf"
    report = tmp_path / "reports" / "r.json"
    code, _, err = bake_cli(capsys, "bake", str(source), "-o", str(output), *FAST,
                            "--report", str(report))
    assert code == 0, err
    assert output.is_file() and output.with_suffix(".bin").is_file() and report.is_file()


def test_a_failed_bake_takes_back_the_folders_it_made(tmp_path, capsys):
    """A bake that fails after making the output's folders (a density no memory holds) leaves
    nothing behind: not the folders either."""
    source = small_scene().save(tmp_path / "scene.glb")
    output = tmp_path / "no" / "such" / "baked.glb"
    before = snapshot(tmp_path)
    code, _, err = bake_cli(capsys, "bake", str(source), "-o", str(output), *FAST,
                            "--texel-density", "1e5")
    assert code == 1
    assert_one_clean_message(err, "--texel-density")
    assert snapshot(tmp_path) == before and not (tmp_path / "no").exists()


def test_an_output_below_a_file_is_refused(tmp_path, capsys):
    source = small_scene().save(tmp_path / "scene.glb")
    (tmp_path / "notes.txt").write_text("a file, not a folder")
    output = tmp_path / "notes.txt" / "sub" / "baked.glb"
    before = snapshot(tmp_path)
    code, _, err = bake_cli(capsys, "bake", str(source), "-o", str(output), *FAST)
    assert code == 1
    assert_one_clean_message(err, str(output), "is a file")
    assert snapshot(tmp_path) == before


def _without_file_permission_override() -> None:
    """In the child: drop CAP_DAC_OVERRIDE and CAP_DAC_READ_SEARCH from the bounding set, so that
    even root obeys file modes after exec (Linux prctl PR_CAPBSET_DROP = 24)."""
    libc = ctypes.CDLL(None, use_errno=True)
    for capability in (1, 2):
        if libc.prctl(24, capability, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def _baker(*argv: str, **kwargs) -> subprocess.Popen:
    """``baker`` as a real process (``python -m baker.cli.main``), from the repository root."""
    return subprocess.Popen([sys.executable, "-m", "baker.cli.main", *argv], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)


@pytest.mark.skipif(sys.platform != "linux", reason="file modes and prctl are Linux-specific here")
def test_output_folder_without_write_permission(tmp_path):
    source = small_scene().save(tmp_path / "scene.glb")
    locked = tmp_path / "locked"
    locked.mkdir()
    (locked / "baked.glb").write_bytes(PREVIOUS)
    locked.chmod(0o555)
    try:
        before = snapshot(tmp_path)
        preexec = _without_file_permission_override if os.geteuid() == 0 else None
        process = _baker("bake", str(source), "-o", str(locked / "baked.glb"), *FAST,
                         preexec_fn=preexec)
        out, err = process.communicate(timeout=120)
        assert process.returncode == 1, err
        assert_one_clean_message(err, str(locked), "permission", "fix: choose a folder you can write to")
        assert snapshot(tmp_path) == before
    finally:
        locked.chmod(0o755)


def test_output_equal_to_input_is_refused_without_overwrite(tmp_path, capsys):
    source = small_scene().save(tmp_path / "scene.glb")
    refuses(tmp_path, capsys, source, str(source), "is the input", "--overwrite", output=source)
    same_via_other_spelling = tmp_path / "." / "scene.glb"
    refuses(tmp_path, capsys, source, "is the input", output=same_via_other_spelling)


def test_a_gltf_output_whose_bin_would_overwrite_the_inputs_bin_is_refused(tmp_path, capsys):
    """scene.gltf keeps its buffer in other.bin; writing other.gltf would replace other.bin."""
    source, document, bin_path = gltf_pair(tmp_path)
    bin_path.rename(tmp_path / "other.bin")
    document["buffers"][0]["uri"] = "other.bin"
    rewrite(source, document)
    refuses(tmp_path, capsys, source, "other.bin", "buffers[0]", "--overwrite",
            output=tmp_path / "other.gltf")


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_overwrite_replaces_the_input_with_its_bake(tmp_path, capsys, suffix):
    source = small_scene().save(tmp_path / f"scene{suffix}")
    original = load(source)
    code, out, err = bake_cli(capsys, "bake", str(source), "-o", str(source), "--overwrite", *FAST)
    assert code == 0, err
    baked = load(source)
    assert len(baked.instances) == len(original.instances)
    assert _every_primitive_lightmapped(baked)
    # Same geometry: the baked positions are the original ones, gathered through the new vertices.
    np.testing.assert_allclose(np.sort(baked.primitives[0].positions, axis=0)[[0, -1]],
                               np.sort(original.primitives[0].positions, axis=0)[[0, -1]])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [f"scene{suffix}", f"scene{suffix}.bake", f"scene{suffix}.bake.json"]
        + (["scene.bin"] if suffix == ".gltf" else []))


def test_overwrite_through_the_python_api(tmp_path):
    source = small_scene().save(tmp_path / "scene.glb")
    with pytest.raises(baker.OutputError, match="is the input"):
        baker.bake(source, source, baker.Settings(rays=2, page_size=64))
    result = baker.bake(source, source, baker.Settings(rays=2, page_size=64), overwrite=True)
    assert result.texels > 0 and _every_primitive_lightmapped(load(source))


def _every_primitive_lightmapped(scene) -> bool:
    document = scene.document
    materials = [document.materials[p.material] for m in document.meshes for p in m.primitives]
    return bool(materials) and all(carried(m) is not None for m in materials)


# ------------------------------------------------------------------------------------------------
# interruption


@pytest.mark.parametrize("module,stage", [(API, "load"), (FULL, "unwrap"), (FULL, "integrate"),
                                          (API, "encode")], ids=["load", "unwrap", "integrate",
                                                                 "encode"])
def test_ctrl_c_during_a_stage_leaves_the_previous_output(tmp_path, capsys, monkeypatch, module,
                                                          stage):
    source = small_scene().save(tmp_path / "scene.glb")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(module, stage, interrupted)
    output = tmp_path / "baked.glb"
    output.write_bytes(PREVIOUS)
    before = snapshot(tmp_path)
    code, out, err = bake_cli(capsys, "bake", str(source), "-o", str(output), *FAST,
                              "--report", str(tmp_path / "report.json"))
    assert code == 130
    assert err.strip() == "baker: interrupted; no output was changed"
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_ctrl_c_while_the_output_is_being_written(tmp_path, capsys, monkeypatch, suffix):
    """Interrupted inside the writer, after its temporary file exists: the temporary goes, the
    previous output (and its .bin) stays."""
    (tmp_path / "in").mkdir()
    source = small_scene().save(tmp_path / "in" / f"scene{suffix}")
    output = tmp_path / f"baked{suffix}"
    output.write_bytes(PREVIOUS)
    output.with_suffix(".bin").write_bytes(PREVIOUS)
    before = snapshot(tmp_path)
    calls = []

    def fsync(fd):
        calls.append(fd)
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", fsync)
    code, _, err = bake_cli(capsys, "bake", str(source), "-o", str(output), *FAST)
    assert code == 130 and calls
    assert snapshot(tmp_path) == before


def test_an_interrupted_run_chunks_starts_no_further_chunk():
    """A KeyboardInterrupt (or any error) in one chunk cancels the chunks still queued: of 100
    chunks on 2 threads, chunk 0 is held until chunk 1 has raised, and then no further chunk
    starts, on either thread (the one that raised takes its next chunk at once, before the
    waiting thread can cancel anything; a loaded machine widens that window)."""
    ran, raised = [], threading.Event()

    def work(chunk):
        ran.append(chunk)
        if chunk == 0:
            assert raised.wait(30)
            time.sleep(0.5)  # the raising thread is past its error by now
        if chunk == 1:
            raised.set()
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_chunks(work, range(100), threads=2)
    time.sleep(0.1)  # nothing may start after run_chunks returned
    assert sorted(ran) == [0, 1], ran


@pytest.mark.parametrize("how,code", [
    pytest.param(signal.SIGTERM, 143, id="SIGTERM"),
    pytest.param(signal.SIGINT, 130, id="SIGINT", marks=pytest.mark.long)])
def test_a_terminated_bake_removes_its_spill_folder(tmp_path, how, code):
    """A bake of 3 parts (533,196 texels: its rows spill to ``.baker-spill-*`` beside the
    output) stopped by SIGTERM (``kill``, a CI timeout) after its first part cleans up as after
    Ctrl-C: no spill folder, no temporary, no output; exit 143 (130 for Ctrl-C)."""
    source = cornell_box().save(tmp_path / "cornell.glb")
    script = ("import signal, sys\n"  # Ctrl-C as a terminal sends it (see _slow_bake_started)
              "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
              "from baker.cli.main import main\nsys.exit(main(sys.argv[1:]))\n")
    process = subprocess.Popen(
        [sys.executable, "-c", script, "bake", str(source), "-o", str(tmp_path / "baked.glb"),
         "--rays", "64", "--texel-density", "142.2"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not any(p.name.startswith(".baker-spill-") and any(p.iterdir())
                  for p in tmp_path.iterdir() if p.is_dir()):
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    before = snapshot(tmp_path)
    process.send_signal(how)
    out, err = process.communicate(timeout=120)
    assert process.returncode == code, err
    assert "Traceback" not in err and err.strip().startswith("baker: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cornell.glb"]
    assert before["cornell.glb"] == (tmp_path / "cornell.glb").read_bytes()


def _slow_bake_started(tmp_path: Path, marker: Path, *args: str) -> subprocess.Popen:
    """A real ``baker bake`` of the Cornell box that takes seconds in ray casting; returns once
    it has started casting rays (its integrate stage touched ``marker``)."""
    source = cornell_box().save(tmp_path / "cornell.glb")
    script = (  # Ctrl-C as a terminal sends it, even where the suite's shell ignores SIGINT
        "import importlib, pathlib, signal, sys\n"
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
        "b = importlib.import_module('baker.pipeline.full')\n"
        "from baker.cli.main import main\n"
        "real = b.integrate\n"
        f"def integrate(*a, **k):\n    pathlib.Path({str(marker)!r}).touch()\n    return real(*a, **k)\n"
        "b.integrate = integrate\n"
        "sys.exit(main(sys.argv[1:]))\n")
    process = subprocess.Popen(
        [sys.executable, "-c", script, "bake", str(source), "-o", str(tmp_path / "baked.glb"),
         "--rays", "4096", "--texel-density", "12", *args],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not marker.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.02)
    time.sleep(0.3)
    assert process.poll() is None, "the bake finished before it could be interrupted"
    return process


def _cpu_seconds(pid: int) -> float:
    """User + system CPU seconds that process ``pid`` (all its threads) has spent so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _children_cpu_seconds() -> float:
    """User + system CPU seconds of this process's children that have been waited for."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


@pytest.mark.parametrize("how,threads", [
    pytest.param(signal.SIGINT, "1", id="SIGINT-1-thread"),
    pytest.param(signal.SIGINT, "2", id="SIGINT-2-threads", marks=pytest.mark.long),
    pytest.param(signal.SIGKILL, "1", id="SIGKILL", marks=pytest.mark.long)])
def test_killing_a_real_bake_leaves_the_previous_output(tmp_path, how, threads):
    """With 2 threads, Ctrl-C cancels the chunks not yet started and waits only for the running
    ones (``parallel.texels_per_chunk``: 64 texels × 4096 rays here, tens of milliseconds): the
    bake spends well under 2 s of CPU after the signal (0.3–0.4 s of wall time measured on a quiet
    machine; 3 s before, when a chunk was 4096 texels). CPU time, not wall time, so that a loaded
    machine does not fail the test: the uninterrupted bake would spend minutes."""
    (tmp_path / "baked.glb").write_bytes(PREVIOUS)
    marker = tmp_path.parent / f"{tmp_path.name}.started"
    process = _slow_bake_started(tmp_path, marker, "--threads", threads)
    before = snapshot(tmp_path)
    children_before = _children_cpu_seconds()
    cpu_at_signal = _cpu_seconds(process.pid)
    process.send_signal(how)
    out, err = process.communicate(timeout=120)
    if how == signal.SIGINT:
        assert process.returncode == 130, err
        assert err.strip().endswith("baker: interrupted; no output was changed")
        after_signal = _children_cpu_seconds() - children_before - cpu_at_signal
        assert after_signal < 2, after_signal  # Ctrl-C stops the bake, not the bake's end
    else:
        assert process.returncode == -signal.SIGKILL
    assert snapshot(tmp_path) == before
    assert (tmp_path / "baked.glb").read_bytes() == PREVIOUS
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("attributes", [0, "POSITION", [1, 2]])
def test_primitive_attributes_that_are_not_an_object_are_named(tmp_path, capsys, attributes):
    """A primitive whose attributes are a number, a string or a list (a fuzzed file) is
    refused naming it, not read as an object."""
    path, document, _ = gltf_pair(tmp_path)
    document["meshes"][1]["primitives"][0]["attributes"] = attributes
    refuses(tmp_path, capsys, rewrite(path, document), "meshes[1].primitives[0].attributes",
            "not a JSON object")


@pytest.mark.parametrize("where", ["emissive strength", "light intensity", "light colour"])
def test_light_past_any_real_one_is_refused_naming_it(tmp_path, capsys, where):
    """Emission or a punctual light of 1e300 (finite, but its square is not) is refused,
    naming the material or light, with the bound; 1e12 still bakes (and reads back)."""
    b = small_scene()
    if where == "emissive strength":
        b.material("lamp", (1, 1, 1), emissive=(1, 1, 1), emissive_strength=1e300)
        b.node("lamp", b.shape_mesh("lamp", quad(0.2, 0.2), material=2), translation=(0, 1, 0))
        at = "materials[2].extensions.KHR_materials_emissive_strength.emissiveStrength"
    else:
        intensity, colour = (1e300, (1, 1, 1)) if where == "light intensity" else (5, (1e300, 1, 1))
        light = b.light("point", intensity=intensity, color=colour)
        b.node("bulb", extensions={"KHR_lights_punctual": {"light": light}}, translation=(0, 1, 0))
        at = "extensions.KHR_lights_punctual.lights[0].intensity"
    path, document, _ = gltf_pair(tmp_path, b)
    refuses(tmp_path, capsys, path, at, "above 1e+30, past any real light")
    text = path.read_text().replace("1e+300", "1000000000000.0")
    code, _, err = bake_cli(capsys, "bake", str(rewrite(path, json.loads(text))), "-o",
                            str(tmp_path / "ok.glb"), *FAST)
    assert code == 0, err
    load(tmp_path / "ok.glb")  # its emissive strengths, up to MAX_LIGHT, read back


def test_a_base_colour_past_any_albedo_is_baked_at_the_bound_with_a_warning(tmp_path, capsys):
    """A baseColorFactor of [0.6, 1e308, 0.2] (the spec's are at most 1; baker bakes up to
    ``MAX_ALBEDO``) bakes the lightmap pages [0.6, MAX_ALBEDO, 0.2] would, byte for byte, and
    the report's warnings name the clamped factor."""
    path, document, _ = gltf_pair(tmp_path)
    box = next(i for i, m in enumerate(document["materials"]) if m["name"] == "box")
    factor = document["materials"][box]["pbrMetallicRoughness"]["baseColorFactor"]
    outputs = []
    for name, value in (("clamped", 1e308), ("bound", MAX_ALBEDO)):
        factor[1] = value
        output, report = tmp_path / name / "baked.glb", tmp_path / f"{name}.json"
        code, _, err = bake_cli(capsys, "bake", str(rewrite(path, document)), "-o", str(output),
                                "--report", str(report), "--lightmaps", str(tmp_path / name),
                                "--no-state", *FAST)
        assert code == 0, err
        pages = sorted(p for p in (tmp_path / name).iterdir() if p.suffix == ".png")
        assert pages
        outputs.append(([p.read_bytes() for p in pages],
                        json.loads(report.read_text())["warnings"]))
    (clamped, warned), (one, quiet) = outputs
    assert clamped == one
    assert any("1e+308" in text and "outside [0, 1000]" in text for text in warned)
    assert not any("outside [0, 1000]" in text for text in quiet)


@pytest.mark.parametrize("values", [{"rays": "64"}, {"rays": 64.0}, {"max_depth": 2.0},
                                    {"texel_density": "5"}, {"threads": None},
                                    {"supersample": True}, {"target_error": "0.01"}])
def test_settings_of_the_wrong_type_are_refused_naming_them(tmp_path, values):
    """From Python, a string, a float count (64.0) or None where a number is asked: a
    SettingsError naming the setting, nothing written (each once a TypeError or ValueError
    deep in the bake)."""
    source = small_scene().save(tmp_path / "scene.glb")
    with pytest.raises(baker.SettingsError) as error:
        baker.bake(source, tmp_path / "out.glb",
                   baker.Settings(**{"rays": 2, "page_size": 64, **values}), state=False)
    (name, value), = values.items()
    assert error.value.message.startswith(f"{name} must be a ") and repr(value) in error.value.message
    assert not (tmp_path / "out.glb").exists()


def test_numpy_numbers_are_settings_like_pythons(tmp_path):
    """numpy's integers and floats (a pipeline's arithmetic) bake as Python's do, to the byte."""
    source = small_scene().save(tmp_path / "scene.glb")
    ours = {"rays": np.int64(4), "page_size": np.int32(64), "d_max": np.float32(0.5)}
    theirs = {"rays": 4, "page_size": 64, "d_max": 0.5}
    for name, values in (("numpy", ours), ("python", theirs)):
        baker.bake(source, tmp_path / f"{name}.glb", baker.Settings(**values), state=False)
    assert (tmp_path / "numpy.glb").read_bytes() == (tmp_path / "python.glb").read_bytes()
