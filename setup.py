"""Build step of baker's own: the package's kernels are compiled before it is installed.

After ``build_py`` has copied the package into the build folder (or, for an editable install,
in the checkout itself), ``assets/warm_kernels.py`` runs small bakes with that copy, so numba
compiles every kernel into its ``__pycache__`` there, and the wheel carries the compiled code:
the first bake and the first rebake after ``pip install`` compile nothing. The cache is keyed by
each module's text and the environment (``baker/jit.py``), so it holds wherever the files are
installed on a machine like this one, and a kernel whose key does not match is compiled as
before. Then the kernels are compiled once more, ahead of time, into the package's extension
module ``baker/_kernels`` (``assets/compile_kernels.py``), which bakes call without importing
numba; where it cannot be built (no C compiler), the install goes on and the bakes use the
cache. A warm-up that fails fails the install, saying why; ``BAKER_NO_WARM=1`` skips it (a
faster install, a slower first bake).

First, the C compiler builds ``baker/native/rays.c``, baker's own Embree calls, into
``baker/_rays.so`` (``baker/rays/native.py``); where it cannot, the install goes on and bakes
cast their rays through embreex.
"""

import os
import shlex
import subprocess
import sys
import sysconfig
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent


class WarmedBuild(build_py):
    """``build_py``, then the built package's kernels compiled into it."""

    def run(self) -> None:
        super().run()
        built = HERE if getattr(self, "editable_mode", False) else Path(self.build_lib).resolve()
        print(_native_rays(built / "baker" / "_rays.so"), flush=True)
        if os.environ.get("BAKER_NO_WARM"):
            return
        # before what is there: pip's isolated build finds its packages (numpy, numba, ...)
        # through the PYTHONPATH it sets, which the warm-up must keep
        path = [str(built), str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])]
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(path))
        env.pop("NUMBA_CACHE_DIR", None)  # the cache goes beside the built modules
        print("compiling baker's kernels into the build (BAKER_NO_WARM=1 skips it)", flush=True)
        done = subprocess.run([sys.executable, str(HERE / "assets" / "warm_kernels.py")], env=env,
                              cwd=built, capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"baker's kernels could not be compiled at install:\n{done.stderr}\n"
                             "set BAKER_NO_WARM=1 to install without (the first bake compiles)")
        print(done.stdout, flush=True)


def _native_rays(target: Path) -> str:
    """Compile baker's Embree calls into ``target`` (its Embree symbols left for the loader:
    ``baker/rays/native.py`` loads embreex's libembree4 first); what happened, to print."""
    if not sys.platform.startswith("linux"):
        return "baker's native ray calls are built on Linux only; rays go through embreex"
    compiler = shlex.split(os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc")
    partial = target.with_suffix(".partial")
    command = [*compiler, "-O2", "-fPIC", "-shared", str(HERE / "baker" / "native" / "rays.c"),
               "-o", str(partial)]
    try:
        done = subprocess.run(command, capture_output=True, text=True)
    except OSError as error:
        return f"no C compiler ({error}): rays go through embreex"
    if done.returncode != 0:
        partial.unlink(missing_ok=True)
        why = done.stderr.strip() or f"{compiler[0]} exited with {done.returncode}"
        return f"baker's native ray calls did not compile ({why}): rays go through embreex"
    partial.replace(target)
    return f"compiled baker's native ray calls into {target}"


setup(cmdclass={"build_py": WarmedBuild})
