"""The files a ``.gltf`` names by URI, read only from inside its own folder.

A glTF file from someone else must not make baker read anything else on the machine: its bytes
would be merged into the output (buffers) or copied beside it (images). So a relative URI is
percent-decoded once (glTF 2.0 §3.3.2: URIs are RFC 3986 references) and then:

- refused when it has a scheme (``http:``, ``file:``) or is an absolute path (``/etc``, ``//x``,
  ``\\\\server``) or holds a NUL;
- resolved with every symbolic link followed (``os.path.realpath``), and refused unless the
  result lies inside the scene's own folder, itself resolved (``../``, ``%2E%2E%2F`` and a
  symlink pointing outside are all the same escape);
- opened without following a link in its last part (``O_NOFOLLOW``: a link swapped in after the
  check is refused) and without blocking (``O_NONBLOCK``: opening a FIFO returns at once), and
  refused unless it is a regular file (no FIFO, socket or device such as ``/dev/zero``);
- read for at most ``limit`` bytes, its size checked against ``limit`` first.

- refused when it has other names (hard links, ``st_nlink`` > 1), unless the bake allows them
  (``Settings.allow_hard_links``): a hard link inside the folder to a file elsewhere (a key, a
  secret of another user's, made by whoever could write to the folder) is the file itself, and
  where its other names are cannot be known (Linux keeps no list of them). Files that git,
  exporters and copies make have one name; deduplicating stores (``cp -al``, rsync
  ``--link-dest``, some package caches) make several.
"""

from __future__ import annotations

import os
import re
import stat
import urllib.parse
from pathlib import Path

from baker.errors import InputError

URI_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")
"""A URI that starts with a scheme (``http:``, ``file:``, ``data:``): not a relative path."""

_KEEP = "keep the files the exporter wrote beside the .gltf (inside its folder), or export a .glb"
_KINDS = {stat.S_IFIFO: "a FIFO", stat.S_IFSOCK: "a socket", stat.S_IFCHR: "a character device",
          stat.S_IFBLK: "a block device", stat.S_IFDIR: "a folder"}


def inside(uri: str, folder: Path, file: str, where: str) -> Path:
    """The real path (no symbolic link in it) of the file the relative ``uri`` names, which lies
    inside ``folder``; an ``InputError`` at ``<where>.uri`` naming the URI otherwise."""
    at = f"{where}.uri"
    if not isinstance(uri, str):
        raise InputError(f"uri {uri!r} is not a string", file=file, where=at, fix=_KEEP)
    shown = uri if len(uri) <= 120 else uri[:117] + "..."
    if URI_SCHEME.match(uri):
        raise InputError(f'uri "{shown}" is not a relative file path: baker reads no URI with '
                         "a scheme (web, file)", file=file, where=at,
                         fix="put the file beside the .gltf and refer to it by a relative path, "
                             "or export a .glb")
    relative = urllib.parse.unquote(uri)
    if "\0" in relative:
        raise InputError(f'uri "{shown}" holds a NUL character', file=file, where=at, fix=_KEEP)
    if relative.startswith(("/", "\\")) or os.path.isabs(relative):
        raise InputError(f'uri "{shown}" is an absolute path: baker reads only files inside the '
                         f"scene's folder {folder}", file=file, where=at, fix=_KEEP)
    root = os.path.realpath(folder)
    target = os.path.realpath(os.path.join(root, relative))
    if os.path.commonpath([root, target]) != root or target == root:
        raise InputError(f'uri "{shown}" leads out of the scene\'s folder {root} (to {target}): '
                         "baker reads only files inside it", file=file, where=at, fix=_KEEP)
    return Path(target)


def read_inside(uri: str, folder: Path, limit: int, file: str, where: str,
                hard_links: bool = False) -> bytes:
    """At most ``limit`` bytes of the regular file inside ``folder`` that the relative ``uri``
    names (see the module's docstring); an ``InputError`` naming ``where`` and the URI when it
    is outside the folder, missing, not a regular file, unreadable, or (unless ``hard_links``)
    a file with other names too."""
    target = inside(uri, folder, file, where)
    at = f"{where}.uri"
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0)
    try:
        descriptor = os.open(target, flags)
    except OSError as exc:
        what = "not found" if isinstance(exc, FileNotFoundError) else f"unreadable ({exc.strerror or exc})"
        raise InputError(f'"{uri}" is {what} (looked for {target})', file=file, where=at,
                         fix=_KEEP) from None
    try:
        info = os.fstat(descriptor)
        if not stat.S_ISREG(info.st_mode):
            kind = _KINDS.get(stat.S_IFMT(info.st_mode), "not a regular file")
            raise InputError(f'"{uri}" is {kind} ({target}), not a regular file: baker reads '
                             "only regular files", file=file, where=at, fix=_KEEP)
        if info.st_nlink > 1 and not hard_links:
            raise InputError(f'"{uri}" ({target}) is a file with {info.st_nlink} names (hard '
                             "links): another may be outside the scene's folder, which cannot be "
                             "known, so baker reads only files with one name", file=file, where=at,
                             fix="copy the file into the folder (cp, not ln), or bake with "
                                 "--allow-hard-links if every name it has is yours")
        stream = open(descriptor, "rb", buffering=0, closefd=False)
        with stream:
            return _read_at_most(stream, min(info.st_size, limit), uri, target, file, at)
    finally:
        os.close(descriptor)


def _read_at_most(stream, count: int, uri: str, target: Path, file: str, at: str) -> bytes:
    """``count`` bytes from ``stream``, or fewer if the file shrank meanwhile."""
    data = bytearray(count)
    view, done = memoryview(data), 0
    try:
        while done < count:
            got = stream.readinto(view[done:])
            if not got:
                break
            done += got
    except OSError as exc:
        raise InputError(f'"{uri}" is unreadable ({exc.strerror or exc}; {target})', file=file,
                         where=at, fix=_KEEP) from None
    del view
    return bytes(data[:done]) if done < count else bytes(data)
