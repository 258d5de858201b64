"""The command line as a user runs it: help, a bake, the report, exit codes."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

import baker
from assets.make_scenes import cornell_box
from baker.cli.main import main


def test_help_explains_every_setting(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["bake", "--help"])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    for option in ("--texel-density", "--page-size", "--padding", "--rays", "--d-max", "--rho",
                   "--seed", "--sampling", "--report", "--lightmaps", "--encoding", "--occlusion"):
        assert option in text, option
    assert "sqrt" in text and "step" in text and "examples:" in text


def test_help_and_the_package_import_no_pipeline():
    """``import baker`` and every subcommand's parser (what ``baker --help`` and a wrong option
    build) load none of the heavy modules: those are imported by the command that runs (the
    start-up, and with it the window where Ctrl-C meets Python's own imports, stays short)."""
    heavy = ("numpy", "numba", "embreex", "PIL", "OpenEXR", "ray", "scipy", "pygltflib")
    code = ("import sys\nimport baker\nfrom baker.cli.main import build_parser\n"
            "parser = build_parser()\nfor name in ('bake', 'rebake', 'relight', 'watch', 'hook',"
            " 'preview', 'view', 'plugin', 'study'):\n    try:\n        parser.parse_args([name, '--help'])\n"
            "    except SystemExit:\n        pass\n"
            f"print([m for m in {heavy!r} if m in sys.modules])")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parent.parent)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "[]"


def test_bake_prints_a_summary_and_writes_the_report(tmp_path, capsys):
    scene = cornell_box().save(tmp_path / "box.glb")
    out, report = tmp_path / "box_baked.glb", tmp_path / "report.json"
    code = main(["bake", str(scene), "-o", str(out), "--rays", "8", "--texel-density", "6",
                 "--report", str(report)])
    printed = capsys.readouterr().out
    assert code == 0 and out.stat().st_size > scene.stat().st_size
    data = json.loads(report.read_text())
    assert f"{data['texels']:,} texels" in printed and "M rays/s" in printed
    assert data["settings"]["rays"] == 8 and data["settings"]["texel_density"] == 6.0
    assert data["settings"]["d_max"] > 0  # the default, derived from the scene and reported
    assert data["rays_per_second"] > 0


def test_an_adaptive_bake_prints_the_rays_its_texels_got(tmp_path, capsys):
    """With ``--target-error`` the summary gives the rays a texel got on average, not the
    first round's (``--rays`` not given: 16)."""
    scene = cornell_box().save(tmp_path / "box.glb")
    out, report = tmp_path / "box_baked.glb", tmp_path / "report.json"
    assert main(["bake", str(scene), "-o", str(out), "--target-error", "0.01",
                 "--texel-density", "6", "--report", str(report)]) == 0
    printed = capsys.readouterr().out
    data = json.loads(report.read_text())
    assert data["settings"]["rays"] == 16 and data["rays"] > 16 * data["texels"]
    assert (f"{data['rays'] / data['texels']:.1f} rays/texel on average (rounds from 16, at "
            f"most 1024)") in printed


def test_a_gi_bake_prints_the_paths_its_texels_got(tmp_path, capsys):
    """``--method gi``: the summary gives the GI paths a texel got (on average, with rounds)
    and the rays they cast, as the report counts them; uniform paths are --rays a texel."""
    scene = cornell_box().save(tmp_path / "box.glb")
    out, report = tmp_path / "box_baked.glb", tmp_path / "report.json"
    for options, rounds in ((["--rays", "4"], False), (["--target-error", "0.1"], True)):
        assert main(["bake", str(scene), "-o", str(out), "--method", "gi", "--texel-density",
                     "3", "--full", "--report", str(report), *options]) == 0
        printed = capsys.readouterr().out
        data = json.loads(report.read_text())
        paths, texels = data["gi"]["paths"], data["texels"]
        assert f"{data['gi']['rays']:,} GI path rays" in printed
        if rounds:
            assert paths > 16 * texels
            assert f"{paths / texels:.1f} GI paths/texel on average (rounds from 16" in printed
        else:
            assert paths == 4 * texels and "4 GI paths/texel, 4 obscurance rays/texel" in printed


def test_quiet_prints_nothing(tmp_path, capsys):
    scene = cornell_box().save(tmp_path / "box.glb")
    assert main(["bake", str(scene), "-o", str(tmp_path / "o.glb"), "--rays", "4",
                 "--texel-density", "4", "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""


def test_a_missing_scene_is_one_message_and_exit_1(tmp_path):
    out = tmp_path / "o.glb"
    run = subprocess.run([sys.executable, "-m", "baker.cli.main", "bake", str(tmp_path / "nope.glb"),
                          "-o", str(out)], capture_output=True, text=True)
    assert run.returncode == 1
    assert "nope.glb" in run.stderr and "Traceback" not in run.stderr
    assert not out.exists()


def test_bad_settings_say_what_to_do(tmp_path, capsys):
    scene = cornell_box().save(tmp_path / "box.glb")
    out = tmp_path / "o.glb"
    assert main(["bake", str(scene), "-o", str(out), "--rays", "0"]) == 1
    err = capsys.readouterr().err
    assert "rays" in err and "--rays" in err
    assert not out.exists()


def test_material_and_sampling_options_reach_the_settings():
    from baker.cli.bake import settings_from
    from baker.cli.main import build_parser

    args = build_parser().parse_args(
        ["bake", "in.glb", "-o", "out.glb", "--specular", "c", "--mirror-roughness", "0.3",
         "--translucent", "0.2", "--max-depth", "5", "--sampling", "random",
         "--target-error", "0.01", "--max-rays", "256", "--method", "gi"])
    s = settings_from(args)
    assert (s.specular, s.mirror_roughness, s.translucent, s.max_depth) == ("c", 0.3, 0.2, 5)
    assert (s.sampling, s.target_error, s.max_rays, s.method) == ("random", 0.01, 256, "gi")


def test_the_command_ignores_a_second_ctrl_c_once_done(tmp_path):
    """``baker`` (``baker.cli.main.entry``) ignores Ctrl-C once its command has returned, so a second
    Ctrl-C while Python ends the worker threads prints no traceback from the interpreter's
    shutdown; the exit code stays the command's. Run in a child process: the test's own
    Ctrl-C stays as it is."""
    script = ("import signal, sys; sys.argv = ['baker', 'bake', sys.argv[1], '-o', sys.argv[2]]; "
              "from baker.cli.main import entry; code = entry(); "
              "print(signal.getsignal(signal.SIGINT) is signal.SIG_IGN); sys.exit(code)")
    run = subprocess.run([sys.executable, "-c", script, str(tmp_path / "nope.glb"),
                          str(tmp_path / "o.glb")],
                         capture_output=True, text=True, cwd=Path(__file__).resolve().parent.parent)
    assert run.returncode == 1 and "baker: error:" in run.stderr
    assert run.stdout.strip() == "True"


def test_every_setting_has_its_option_and_the_same_default():
    """``settings_from`` takes every ``Settings`` field the parser knows: a bake with no option
    asks for ``Settings()`` exactly, and only the two internal fields have no option."""
    import dataclasses

    from baker.cli.bake import settings_from
    from baker.cli.main import build_parser

    args = build_parser().parse_args(["bake", "in.glb", "-o", "out.glb"])
    assert settings_from(args) == baker.Settings()
    missing = {f.name for f in dataclasses.fields(baker.Settings) if not hasattr(args, f.name)}
    assert missing == {"chunk_texels", "d_max_fraction"}


def test_a_bake_that_bakes_nothing_says_so_and_exits_4(tmp_path, capsys):
    """SimpleInstancing's meshes are all GPU-instanced (occluders only): 0 texels. The bake
    writes the scene without a lightmap, says on stderr that nothing was baked and why, and
    exits 4 (README's exit codes), not 0 as a bake that baked something."""
    from bakehelp import REAL_SCENES

    out = tmp_path / "i.glb"
    code = main(["bake", str(REAL_SCENES["SimpleInstancing"]), "-o", str(out), "--rays", "4",
                 "--page-size", "64", "--quiet"])
    captured = capsys.readouterr()
    assert code == 4 and out.is_file() and captured.out == ""
    assert captured.err.startswith("baker: nothing baked") and "0 texels" in captured.err
    assert "125 × GPU-instanced" in captured.err


def test_relight_says_what_it_recomposes_and_refuses_an_emission_change(tmp_path, capsys):
    """``baker relight --help`` lists only punctual lights' colour and intensity as what it
    recomposes, and names emissive changes as refused; an emissive strength change is indeed
    refused (exit 1, nothing written), so the help promises nothing relight does not do."""
    from assets.light_scenes import emissive_square

    with pytest.raises(SystemExit):
        main(["relight", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "emissive strength)" not in text and "emissive material's colour or strength" in text
    scene, out = tmp_path / "lamp.glb", tmp_path / "lamp_baked.glb"
    emissive_square().save(scene)
    assert main(["bake", str(scene), "-o", str(out), "--rays", "4", "--page-size", "32",
                 "--quiet"]) == 0
    emissive_square(radiance=5.0).save(scene)
    before = out.read_bytes()
    assert main(["relight", str(scene), "-o", str(out)]) == 1
    assert "beyond its base colour" in capsys.readouterr().err and out.read_bytes() == before


def test_report_dash_writes_the_json_alone_to_stdout(tmp_path, capsys, monkeypatch):
    """``--report -``: stdout is the JSON report and nothing else (a pipe into ``jq`` works),
    the bake's summary is on stderr, and no file named ``-`` is written."""
    monkeypatch.chdir(tmp_path)
    scene = cornell_box().save(tmp_path / "box.glb")
    code = main(["bake", str(scene), "-o", "box_baked.glb", "--rays", "4", "--texel-density",
                 "4", "--report", "-", "--no-state"])
    printed = capsys.readouterr()
    report = json.loads(printed.out)
    assert code == 0 and report["settings"]["rays"] == 4
    assert f"{report['texels']:,} texels" in printed.err
    assert not (tmp_path / "-").exists()


def test_a_texture_left_out_for_want_of_a_package_is_said_under_quiet(tmp_path, capsys,
                                                                      monkeypatch):
    """A KTX 2 texture without opengl-basisu (``baker[ktx2]``) bakes with its factor; even with
    ``--quiet`` stderr names the package that would read it, and so does the report."""
    import alktx2

    from tests.test_exported_assets import GRADIENT, _texture_scene

    data = alktx2.encode_raw_rgba_to_ktx2(GRADIENT.tobytes(), 32, 32, False)
    scene = _texture_scene(tmp_path, data, "KHR_texture_basisu", "albedo.ktx2")
    monkeypatch.setitem(sys.modules, "opengl_basisu", None)
    code = main(["bake", str(scene), "-o", str(tmp_path / "baked.glb"), "--rays", "4",
                 "--quiet", "--no-state", "--report", str(tmp_path / "report.json")])
    printed = capsys.readouterr()
    assert code == 0 and printed.out == ""
    assert 'pip install "baker[ktx2]"' in printed.err
    warnings = json.loads((tmp_path / "report.json").read_text())["warnings"]
    assert any('pip install "baker[ktx2]"' in text for text in warnings)
