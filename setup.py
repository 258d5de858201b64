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
"""

import os
import subprocess
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent


class WarmedBuild(build_py):
    """``build_py``, then the built package's kernels compiled into it."""

    def run(self) -> None:
        super().run()
        if os.environ.get("BAKER_NO_WARM"):
            return
        built = HERE if getattr(self, "editable_mode", False) else Path(self.build_lib).resolve()
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


setup(cmdclass={"build_py": WarmedBuild})
