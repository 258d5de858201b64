"""What Blender shows of each carrier: its glTF importer and a Cycles render against ``baker preview``.

    python benchmarks/bench_blender.py   # needs blender and numpy for it (Debian: apt-get install
                                         # blender python3-numpy)
    python benchmarks/bench_blender.py --bpy V/bin/python --scenes cornell metal_glass MultiUVTest
                                         # Blender 4.5 LTS as a module: python -m venv V &&
                                         # V/bin/pip install "bpy==4.5.*" numpy (Python 3.11)

Bakes the demo Cornell box (``--scenes``: also the room of metals and glass and the shared
scenes) with each carrier (texel density 8, 16 rays), then for each file runs Blender in
background mode (``blender -b --factory-startup``, or the ``bpy`` module): its glTF importer reads
the file, and the script prints what the importer made of the bake in each baked material
(which Principled BSDF input an image feeds, on which UV map, what the base colour is) and
renders the scene with Cycles on the CPU (16 samples, no denoising, the world black: no light
but the file's; Standard view transform, exposure log2 of the preview's) from the preview's
camera (glTF's +y up is Blender's +z), back faces of single-sided materials see-through as the
preview and glTF viewers cull them (Cycles ignores the importer's backface culling flag). The
picture is compared with the preview's as tests/test_browser.py compares a browser's (median
luminance ratio, log-luminance correlation, lit pixels black). Not a test: Blender is 90–370 MB
and a render takes seconds; docs/viewers.md quotes it.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import baker  # noqa: E402
from assets.make_scenes import cornell_box  # noqa: E402
from assets.material_scenes import metal_glass_room  # noqa: E402
from tests.bakehelp import REAL_SCENES  # noqa: E402
from tests.test_browser import SIZE, _compare, _view_and_preview  # noqa: E402

CARRIERS = ("moz", "emissive", "occlusion")

# Runs inside Blender: argv after "--" is the glTF file, the PNG to write, the camera as
# eye(3), right(3), up(3), back(3) in glTF space, the vertical field of view (radians), the
# exposure factor.
_IN_BLENDER = r'''
import json, math, sys
import numpy
numpy.bool = bool  # Blender 3.4's importer uses numpy.bool, which Debian's numpy 1.24 no longer has
import bpy
from mathutils import Matrix, Vector
args = sys.argv[sys.argv.index("--") + 1:]
model, png = args[0], args[1]
v = [float(x) for x in args[2:]]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=model)
def to_blender(x, y, z):  # glTF +y up -> Blender +z up
    return Vector((x, -z, y))
def cull_back_faces(material):  # Cycles ignores use_backface_culling: see through back faces
    tree = material.node_tree
    output = next(n for n in tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output)
    shader = output.inputs["Surface"].links[0].from_socket
    mix = tree.nodes.new("ShaderNodeMixShader")
    tree.links.new(tree.nodes.new("ShaderNodeNewGeometry").outputs["Backfacing"], mix.inputs[0])
    tree.links.new(shader, mix.inputs[1])
    tree.links.new(tree.nodes.new("ShaderNodeBsdfTransparent").outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], output.inputs["Surface"])
found = {"images": sorted(i.name for i in bpy.data.images), "materials": {}}
for material in bpy.data.materials:
    if not material.use_nodes:
        continue
    inputs = {}
    for node in material.node_tree.nodes:
        if node.type != "TEX_IMAGE" or node.image is None:
            continue
        uv = "default"
        if node.inputs["Vector"].is_linked:
            source = node.inputs["Vector"].links[0].from_node
            uv = getattr(source, "uv_map", source.type)
        for link in node.outputs["Color"].links:
            inputs.setdefault(link.to_socket.name + " of " + link.to_node.name, []).append(
                {"image": node.image.name, "uv": uv,
                 "colorspace": node.image.colorspace_settings.name})
    bsdf = next((n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
    found["materials"][material.name] = {
        "inputs": inputs,
        "base": list(bsdf.inputs["Base Color"].default_value)[:3] if bsdf else None,
        "emission strength": bsdf.inputs["Emission Strength"].default_value if bsdf else None,
        "metallic": bsdf.inputs["Metallic"].default_value if bsdf else None,
        "roughness": bsdf.inputs["Roughness"].default_value if bsdf else None}
    if material.use_backface_culling:
        cull_back_faces(material)
found["uv maps"] = sorted({uv.name for o in bpy.data.objects if o.type == "MESH"
                           for uv in o.data.uv_layers})
scene = bpy.context.scene
world = bpy.data.worlds.new("black")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
scene.world = world
camera = bpy.data.cameras.new("view")
camera.sensor_fit = "VERTICAL"
camera.angle_y = v[12]
camera.clip_start, camera.clip_end = 1e-3, 1e4
eye = bpy.data.objects.new("view", camera)
scene.collection.objects.link(eye)
right, up, back = (to_blender(*v[i:i + 3]) for i in (3, 6, 9))
eye.matrix_world = Matrix((
    (right.x, up.x, back.x, 0), (right.y, up.y, back.y, 0), (right.z, up.z, back.z, 0),
    (0, 0, 0, 1)))
eye.location = to_blender(*v[0:3])
scene.camera = eye
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 16
scene.cycles.use_denoising = False
scene.render.threads_mode = "FIXED"
scene.render.threads = 2
scene.render.resolution_x, scene.render.resolution_y = int(v[14]), int(v[15])
scene.render.resolution_percentage = 100
scene.view_settings.view_transform = "Standard"
scene.view_settings.look = "None"
scene.view_settings.exposure = math.log2(v[13])
scene.render.image_settings.file_format = "PNG"
scene.render.filepath = png
bpy.ops.render.render(write_still=True)
print("BAKER-FOUND " + json.dumps(found))
'''


def _blender_env() -> dict:
    """The environment for Debian's Blender: its Python takes its home from the first python3
    on PATH, so the system's goes first (a pyenv one has no numpy, which the glTF importer
    needs: Debian's python3-numpy)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYENV")}
    env["PATH"] = "/usr/bin:/bin:" + env.get("PATH", "")
    return env


def blender_picture(runner: list[str], model: Path, png: Path, view, exposure: float) -> dict:
    """Render ``model`` with Blender (``runner``: the command that runs a Python script in it) to
    ``png``; returns what the importer made of it."""
    right, up, back = view.axes
    values = [*view.origin, *right, *up, *back, view.yfov, exposure, *SIZE]
    run = subprocess.run([*runner, _IN_BLENDER, "--", str(model), str(png),
                          *(f"{x:.9g}" for x in values)],
                         capture_output=True, text=True, timeout=900, env=_blender_env())
    lines = [line for line in run.stdout.splitlines() if line.startswith("BAKER-FOUND ")]
    if run.returncode != 0 or not lines:
        raise RuntimeError(f"blender failed on {model}:\n{run.stdout[-3000:]}{run.stderr[-3000:]}")
    return json.loads(lines[-1].split(" ", 1)[1])


SCENES = {"cornell": lambda folder: cornell_box().save(folder / "cornell.glb"),
          "metal_glass": lambda folder: metal_glass_room().save(folder / "metal_glass.glb"),
          **{name: (lambda folder, path=path: path) for name, path in REAL_SCENES.items()
             if name != "SimpleInstancing"}}  # (GPU instances only: nothing baked)


def runner(bpy_python: str | None) -> list[str]:
    """The command that runs a Python script (``-c``-style, then ``--`` and its arguments) in
    Blender: the ``bpy`` module in the Python at ``bpy_python`` (pip install bpy: Blender 4.5
    LTS), else the ``blender`` program on PATH (Debian's)."""
    if bpy_python is not None:
        return [bpy_python, "-c"]
    blender = shutil.which("blender")
    if blender is None:
        sys.exit("no blender on PATH (Debian: apt-get install blender), and no --bpy python")
    return [blender, "-b", "--factory-startup", "--python-expr"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bpy", metavar="PYTHON",
                        help="a Python with the bpy module (python -m venv V && V/bin/pip install "
                             "bpy==4.5.* numpy) instead of the blender program")
    parser.add_argument("--carriers", nargs="+", default=list(CARRIERS), choices=CARRIERS)
    parser.add_argument("--scenes", nargs="+", default=["cornell"], choices=list(SCENES))
    args = parser.parse_args()
    command = runner(args.bpy)
    version = subprocess.run([*command, "import bpy; print('Blender', bpy.app.version_string)",
                              "--"], capture_output=True, text=True, env=_blender_env()).stdout
    print(version.strip().splitlines()[-1] if version.strip() else "Blender (version unknown)")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name in args.scenes:
            source = SCENES[name](folder)
            for carrier in args.carriers:
                out = folder / f"{name}_{carrier}.glb"
                density = 8.0 if name in ("cornell", "metal_glass") else 4.0
                baker.bake(source, out, baker.Settings(texel_density=density, rays=16,
                                                       carrier=carrier), state=False)
                view, preview = _view_and_preview(out)
                png = folder / f"blender_{name}_{carrier}.png"
                found = blender_picture(command, out, png, view, preview.exposure)
                print(f"\n{name} {carrier}: images {found['images']}, UV maps {found['uv maps']}")
                for material_name, material in found["materials"].items():
                    print(f"  {material_name}: {material}")
                shown = np.asarray(Image.open(png).convert("RGB"))
                _compare(shown, preview, f"blender_{name}_{carrier}", ROOT / "out")


if __name__ == "__main__":
    (ROOT / "out").mkdir(exist_ok=True)
    main()
