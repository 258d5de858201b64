"""Build step of baker's own: the built package is warmed before it is packed.

After ``build_py`` has copied the package into the build folder, ``assets/warm_kernels.py`` runs
small bakes with that copy, so numba compiles every kernel into its ``__pycache__`` there, and
the wheel carries the compiled code: the first bake after ``pip install`` does not compile
(numba keys its cache by a hash of each module's source, the argument types and the CPU, so
the cache holds wherever the files are installed on this machine, and a kernel whose key does
not match is compiled as before). Set ``BAKER_NO_WARM=1`` to skip it (a faster install, a slower
first bake); a warm-up that fails only says so.
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
        if getattr(self, "editable_mode", False) or os.environ.get("BAKER_NO_WARM"):
            return
        built = Path(self.build_lib).resolve()
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(built), str(HERE)]))
        env.pop("NUMBA_CACHE_DIR", None)  # the cache goes beside the built modules
        print("compiling baker's kernels into the build (BAKER_NO_WARM=1 skips it)", flush=True)
        done = subprocess.run([sys.executable, str(HERE / "assets" / "warm_kernels.py")], env=env,
                              cwd=built)
        if done.returncode != 0:
            print("warning: baker's kernels were not compiled at install; the first bake will "
                  "compile them", flush=True)


setup(cmdclass={"build_py": WarmedBuild})
