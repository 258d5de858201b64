"""The two ways baker compiles its kernels with numba: ``jit`` and ``inline``.

Every kernel is compiled ``nogil`` (the bake's threads run them side by side) and cached on
disk beside its module (``__pycache__``), so a process pays the compile once per install.
"""

from __future__ import annotations

import numba

jit = numba.njit(nogil=True, cache=True)
# For helpers that take arrays and run once per texel or ray inside a kernel: inlined into the
# kernels that call them (numba IR), where a call passing arrays costs several times their
# arithmetic (``rebake.incremental._near_flags``: 907 -> 105 ns a texel of 64 rays).
inline = numba.njit(nogil=True, cache=True, inline="always")
