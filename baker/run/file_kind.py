"""What a file is, in words, for messages that refuse it: "a FIFO", "a folder", …"""

from __future__ import annotations

import stat

_KINDS = {stat.S_IFIFO: "a FIFO", stat.S_IFSOCK: "a socket", stat.S_IFCHR: "a character device",
          stat.S_IFBLK: "a block device", stat.S_IFDIR: "a folder", stat.S_IFLNK: "a symbolic link",
          stat.S_IFREG: "a regular file"}


def kind_of(mode: int | None) -> str:
    """What a file of ``st_mode`` ``mode`` is ("a FIFO", "a folder", "a regular file", …;
    "nothing" for None: a link to no file)."""
    if mode is None:
        return "nothing"
    return _KINDS.get(stat.S_IFMT(mode), "not a regular file")
