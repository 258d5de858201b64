"""Make the README's images: one function per image, each writing docs/images/NAME.png.

    python docs/make_images.py            # every image
    python docs/make_images.py study      # only those named

Each function builds its scene with ``assets/make_scenes.py`` in a temporary folder, runs baker
on it and writes its image; what it prints is what the README quotes beside the image.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from assets.make_scenes import cornell_box  # noqa: E402
from baker.cli.main import main as baker_main  # noqa: E402

IMAGES = ROOT / "docs" / "images"


def study(out: Path = IMAGES / "study.png") -> Path:
    """``baker study`` on the demo Cornell room (its defaults: 128² page, 4 … 1024 rays per texel,
    each technique, full-GI comparison): RMSE against seconds. Prints the table and the run's
    wall time (the issue asks under 5 minutes on 2 cores)."""
    with tempfile.TemporaryDirectory() as folder:
        scene = cornell_box().save(Path(folder) / "cornell_box.glb")
        started = time.perf_counter()
        assert baker_main(["study", str(scene), "--plot", str(out)]) == 0
        print(f"baker study: {time.perf_counter() - started:.0f} s wall time")
    return out


def preview(out: Path = IMAGES / "preview.png") -> Path:
    """``baker preview`` of the demo Cornell box (the scene ``python assets/make_scenes.py``
    writes to assets/scenes/cornell_box.glb), baked at the defaults but 256 rays per texel:
    albedo × lightmap at 480 × 360 from the default view (the room is seen from outside through
    its culled near walls). Prints the bake's and the preview's wall times and the file size."""
    with tempfile.TemporaryDirectory() as folder:
        scene = cornell_box().save(Path(folder) / "cornell_box.glb")
        baked = Path(folder) / "cornell_box_baked.glb"
        started = time.perf_counter()
        assert baker_main(["bake", str(scene), "-o", str(baked), "--rays", "256", "--quiet",
                           "--no-state"]) == 0
        baked_at = time.perf_counter()
        assert baker_main(["preview", str(baked), "-o", str(out), "--size", "480x360",
                           "--quiet"]) == 0
        print(f"bake {baked_at - started:.1f} s, preview {time.perf_counter() - baked_at:.1f} s, "
              f"{out.stat().st_size / 1024:.0f} KiB")
    return out


def view(out: Path = IMAGES / "view.png") -> Path:
    """``baker view``'s page in headless Chromium (tests/chromium.py: Debian's package, WebGL
    through SwiftShader), 720 × 480, showing the demo Cornell box baked as for ``preview``."""
    sys.path.insert(0, str(ROOT / "tests"))
    from chromium import Browser, find_chromium

    from baker.view import start

    with tempfile.TemporaryDirectory() as folder:
        scene = cornell_box().save(Path(folder) / "cornell_box.glb")
        baked = Path(folder) / "cornell_box_baked.glb"
        assert baker_main(["bake", str(scene), "-o", str(baked), "--rays", "256", "--quiet",
                           "--no-state"]) == 0
        server, url = start(baked)
        try:
            with Browser(find_chromium()) as browser:
                out.write_bytes(browser.page_png(url, 720, 480))
        finally:
            server.shutdown()
    print(f"{out.stat().st_size / 1024:.0f} KiB")
    return out


IMAGE_FUNCTIONS = {"preview": preview, "study": study, "view": view}


def main(names: list[str]) -> None:
    """Make the images named (default: all)."""
    IMAGES.mkdir(parents=True, exist_ok=True)
    for name in names or IMAGE_FUNCTIONS:
        print(f"{name}: {IMAGE_FUNCTIONS[name]()}")


if __name__ == "__main__":
    main(sys.argv[1:])
