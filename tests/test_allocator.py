"""The command line's allocator settings: arrays made after bigger ones were freed reuse their
memory instead of faulting in new pages (``baker.run.allocator``)."""

import platform
import subprocess
import sys

import pytest

# Measured in a new process: a 7 MiB array touched and freed, then arrays of 1 to 6 MiB made
# and touched in turn (all below ``MMAP_THRESHOLD``); prints the minor page faults of that second
# phase.
_FAULTS = """
import resource, sys
import numpy as np
from baker.run.allocator import keep_freed_memory
if sys.argv[1] == "kept":
    assert keep_freed_memory()
first = np.ones(7 << 17)  # 7 MiB of float64
del first
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for mib in (1, 2, 4, 6):
    block = np.ones(mib << 17)
    del block
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> int:
    done = subprocess.run([sys.executable, "-c", _FAULTS, mode], capture_output=True, text=True,
                          check=True)
    return int(done.stdout)


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="the settings are glibc's malloc's")
def test_arrays_after_a_freed_bigger_one_reuse_its_pages():
    pages = (1 + 2 + 4 + 6) << 8  # 4 KiB pages the second phase touches: 3,328
    kept, default = _faults("kept"), _faults("default")
    assert kept < pages / 20, kept  # the freed 7 MiB reused: no new page to fault in
    # glibc's own settings fault in about half of them (1,529 on glibc 2.36): its adaptive
    # threshold keeps some of what was freed, not all
    assert default > pages / 8, default


def test_settings_are_taken_where_glibc_is_the_c_library():
    """True where the C library is glibc (its mallopt took both settings), else False with
    nothing changed; asked in a new process, which the settings then hold for its life."""
    done = subprocess.run([sys.executable, "-c", "import platform\n"
                           "from baker.run.allocator import keep_freed_memory\n"
                           "print(keep_freed_memory(), platform.libc_ver()[0] == 'glibc')"],
                          capture_output=True, text=True, check=True)
    taken, glibc = done.stdout.split()
    assert taken == glibc, done.stdout
