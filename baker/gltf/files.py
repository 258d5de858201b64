"""The files a ``.gltf`` names by URI, opened once, only from inside its own folder.

A glTF file from someone else must not make baker read anything else on the machine: its bytes
would be merged into the output (buffers) or copied beside it (images). So the scene's folder is
opened once, as a directory descriptor (``SceneFolder``), and every file a URI names is opened
relative to that descriptor, one path component at a time, never by a path looked up again:

- a URI with a scheme (``http:``, ``file:``), an absolute path (``/etc``, ``//x``,
  ``\\\\server``) or a NUL is refused; a relative one is percent-decoded once (glTF 2.0 §3.3.2:
  URIs are RFC 3986 references);
- each folder on the way is opened without following a symbolic link (``O_NOFOLLOW``) relative
  to the one before; ``..`` goes back to the folder walked before it, and past the scene's
  folder is refused. A symbolic link met on the way is read (``readlinkat``) and its target
  walked the same way from where the link lies, so a link that stays inside the folder is
  followed and one that leads out of it (``../x``, ``/etc``, ``/dev/zero``) is refused. A folder
  swapped for a link while the walk runs is met as the link, never followed blindly: nothing the
  walk opens lies outside the descriptor it started from;
- the file itself is opened without following a link and without blocking (``O_NONBLOCK``:
  opening a FIFO returns at once), and refused unless that descriptor is a regular file (no
  FIFO, socket, device or folder), of at most the bytes the caller may read (its size is
  checked on the same descriptor, before a byte is read);
- refused when it has other names (hard links, ``st_nlink`` > 1), unless the bake allows them
  (``Settings.allow_hard_links``): a hard link inside the folder to a file elsewhere (a key, a
  secret of another user's, made by whoever could write to the folder) is the file itself, and
  where its other names are cannot be known (Linux keeps no list of them). Files that git,
  exporters and copies make have one name; deduplicating stores (``cp -al``, rsync
  ``--link-dest``, some package caches) make several.

Every file opened is recorded by its identity (device, inode: ``SceneFolder.opened``), so that
no file a bake writes ever replaces one the scene was read from, whatever its name
(``run.atomic.Outputs``).
"""

from __future__ import annotations

import errno
import os
import re
import stat
import urllib.parse
from pathlib import Path

from baker.errors import InputError
from baker.run.file_kind import kind_of

URI_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")
"""A URI that starts with a scheme (``http:``, ``file:``, ``data:``): not a relative path."""
MAX_LINKS = 40
"""Most symbolic links one URI may lead through (Linux's own limit for a path)."""

_KEEP = "keep the files the exporter wrote beside the .gltf (inside its folder), or export a .glb"
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
_FOLDER = getattr(os, "O_PATH", os.O_RDONLY) | os.O_DIRECTORY | os.O_NOFOLLOW | _CLOEXEC
_FILE = (os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW | _CLOEXEC | getattr(os, "O_BINARY", 0))
_LINK_ERRORS = (errno.ELOOP, errno.EMLINK, errno.ENOTDIR)  # what O_NOFOLLOW says of a link


def relative_path(uri: str, folder: Path, file: str, at: str) -> str:
    """The relative path a glTF ``uri`` names, percent-decoded once; an ``InputError`` at ``at``
    (the URI's JSON path) when it is not a string, has a scheme, holds a NUL or is absolute."""
    if not isinstance(uri, str):
        raise InputError(f"uri {uri!r} is not a string", file=file, where=at, fix=_KEEP)
    shown = _shown(uri)
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
    return relative


def _shown(uri: str) -> str:
    return uri if len(uri) <= 120 else uri[:117] + "..."


class SceneFolder:
    """The folder of a scene, opened once (see the module's docstring): ``open``/``read`` the
    files its URIs name inside it, and the scene file itself (``read_scene``). ``file``: the
    scene's path, for messages; ``hard_links``: files with other names too may be read. Use as
    a context manager (or ``close``)."""

    def __init__(self, folder: Path, file: str, hard_links: bool = False):
        self.folder, self.file, self.hard_links = Path(folder), file, hard_links
        self.opened: dict[tuple[int, int], str] = {}  # (device, inode) → what the scene reads it as
        try:
            self._descriptor = os.open(self.folder, _FOLDER & ~os.O_NOFOLLOW)
        except OSError as exc:
            what = ("file not found: its folder does not exist" if exc.errno == errno.ENOENT
                    else f"cannot open its folder {self.folder} ({exc.strerror or exc})")
            raise InputError(what, file=file, fix="check the path and the file name") from None
        # Only to tell whether an absolute link target lies inside: the walk itself never
        # looks up a path, so a stale name here cannot lead it out of the descriptor.
        self._real = os.path.realpath(self.folder)

    def __enter__(self) -> "SceneFolder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Close the folder's descriptor (the files read stay recorded in ``opened``)."""
        if self._descriptor >= 0:
            os.close(self._descriptor)
            self._descriptor = -1

    def read(self, uri: str, at: str, most: int) -> bytes:
        """At most ``most`` bytes of the regular file inside the folder that the relative ``uri``
        (at the JSON path ``at``) names: refused (``InputError``) when it is outside, missing,
        not a regular file, unreadable or (unless ``hard_links``) a file with other names too."""
        descriptor, size = self.open(uri, at)
        try:
            return read_descriptor(descriptor, min(size, most), uri, self.file, at)
        finally:
            os.close(descriptor)

    def open(self, uri: str, at: str) -> tuple[int, int]:
        """(descriptor, size in bytes) of the file ``read`` reads, opened and checked, not read;
        the caller closes it."""
        relative = relative_path(uri, self.folder, self.file, at)
        return self._checked(self._walk(uri, relative, at), uri, relative, at)

    def read_scene(self, path: Path, contained: bool, most: int) -> bytes:
        """The bytes of the scene file ``path`` (in this folder), refused when it is not a
        regular file or has more than ``most`` bytes. ``contained``: opened as the files it
        names are (no link out of the folder, one name); else as the user named it (a link
        followed)."""
        if contained:
            descriptor = self._walk(path.name, path.name, "")
        else:
            try:
                descriptor = os.open(path, _FILE & ~os.O_NOFOLLOW)
            except OSError as exc:
                what = ("file not found" if exc.errno == errno.ENOENT
                        else f"cannot read the file ({exc.strerror or exc})")
                raise InputError(what, file=self.file,
                                 fix="check the path and the file name") from None
        descriptor, size = self._checked(descriptor, path.name, path.name, "", contained)
        try:
            if size > most:
                raise InputError(f"the scene file is {size:,} bytes, more than baker reads "
                                 f"({most:,})", file=self.file,
                                 fix="give baker a .gltf or .glb file")
            return read_descriptor(descriptor, size, path.name, self.file, "")
        finally:
            os.close(descriptor)

    def append_to(self, name: str, most: int) -> tuple[int, bytes] | None:
        """(descriptor, contents) of the file ``name`` directly in this folder, opened once to
        read and append to (made empty if missing, with the permissions a new file gets), or
        None when it has more than ``most`` bytes; refused (``InputError``) when it is a
        symbolic link (never written through), not a regular file, or has other names. For
        ``baker hook``'s ``.gitignore``; the caller closes the descriptor."""
        try:
            descriptor = os.open(name, (_FILE & ~os.O_RDONLY) | os.O_RDWR | os.O_CREAT
                                 | os.O_APPEND, 0o666, dir_fd=self._descriptor)
        except OSError as exc:
            what = ("a symbolic link: baker does not write through it"
                    if exc.errno in _LINK_ERRORS else f"unwritable ({exc.strerror or exc})")
            raise InputError(f"{name} is {what}", file=str(self.folder / name),
                             fix=f"edit {name} yourself") from None
        descriptor, size = self._checked(descriptor, name, name, name)
        if size > most:
            os.close(descriptor)
            return None
        try:
            return descriptor, read_descriptor(descriptor, size, name, self.file, name)
        except BaseException:
            os.close(descriptor)
            raise

    def _checked(self, descriptor: int, uri: str, relative: str, at: str,
                 one_name: bool = True) -> tuple[int, int]:
        """(``descriptor``, its size) once checked to be a regular file of one name (unless
        ``hard_links`` or not ``one_name``), recorded in ``opened``; closed if refused."""
        try:
            info = os.fstat(descriptor)
            shown, path = _shown(uri), self.folder / relative
            if not stat.S_ISREG(info.st_mode):
                raise InputError(f'"{shown}" is {kind_of(info.st_mode)} ({path}), not a regular '
                                 "file: baker reads only regular files", file=self.file,
                                 where=at, fix=_KEEP)
            if info.st_nlink > 1 and one_name and not self.hard_links:
                raise InputError(f'"{shown}" ({path}) is a file with {info.st_nlink} names (hard '
                                 "links): another may be outside the scene's folder, which "
                                 "cannot be known, so baker reads only files with one name",
                                 file=self.file, where=at,
                                 fix="copy the file into the folder (cp, not ln), or bake with "
                                     "--allow-hard-links if every name it has is yours")
        except BaseException:
            os.close(descriptor)
            raise
        self.opened[(info.st_dev, info.st_ino)] = at or "the scene file"
        return descriptor, info.st_size

    def _walk(self, uri: str, relative: str, at: str) -> int:
        """The descriptor of the file ``relative`` names, opened one component at a time from
        the folder's descriptor (see the module's docstring)."""
        parts = [p for p in relative.split("/") if p not in ("", ".")]
        parts.reverse()  # a stack: the next component last
        walked: list[int] = []  # descriptors of the folders entered, the innermost last
        links = 0
        try:
            while parts:
                name = parts.pop()
                if name == "..":
                    if not walked:
                        raise self._out(uri, at)
                    os.close(walked.pop())
                    if not parts:
                        raise InputError(f'"{_shown(uri)}" names a folder, not a file',
                                         file=self.file, where=at, fix=_KEEP)
                    continue
                here = walked[-1] if walked else self._descriptor
                try:
                    opened = os.open(name, _FOLDER if parts else _FILE, dir_fd=here)
                except OSError as exc:
                    target = _link(name, here) if exc.errno in _LINK_ERRORS else None
                    if target is None:
                        raise self._unopened(uri, relative, exc, at) from None
                    links += 1
                    if links > MAX_LINKS:
                        raise InputError(f'"{_shown(uri)}" leads through more than {MAX_LINKS} '
                                         "symbolic links", file=self.file, where=at, fix=_KEEP)
                    if os.path.isabs(target):
                        inner = os.path.relpath(target, self._real)
                        if inner == ".." or inner.startswith("../"):
                            raise self._out(uri, at, name, target) from None
                        while walked:  # the target is walked from the scene's folder
                            os.close(walked.pop())
                        target = inner
                    parts.extend(reversed([p for p in target.split("/") if p not in ("", ".")]))
                    continue
                if not parts:
                    return opened
                walked.append(opened)
            raise InputError(f'"{_shown(uri)}" names the scene\'s folder itself, not a file',
                             file=self.file, where=at, fix=_KEEP)
        finally:
            for descriptor in walked:
                os.close(descriptor)

    def _out(self, uri: str, at: str, link: str | None = None, target: str | None = None
             ) -> InputError:
        through = f" through the symbolic link {link} (to {target})" if link else ""
        return InputError(f'uri "{_shown(uri)}" leads out of the scene\'s folder {self._real}'
                          f"{through}: baker reads only files inside it", file=self.file,
                          where=at, fix=_KEEP)

    def _unopened(self, uri: str, relative: str, exc: OSError, at: str) -> InputError:
        what = ("not found" if exc.errno in (errno.ENOENT, errno.ENOTDIR)
                else f"unreadable ({exc.strerror or exc})")
        return InputError(f'"{_shown(uri)}" is {what} (looked for {self.folder / relative})',
                          file=self.file, where=at, fix=_KEEP)


def _link(name: str, folder: int) -> str | None:
    """The target of the symbolic link ``name`` in the folder ``folder`` (a descriptor), or
    None when it is no link (any more)."""
    try:
        return os.readlink(name, dir_fd=folder)
    except OSError:
        return None


_PIECE = 1 << 28  # bytes read at once: a signal is handled between pieces


def read_descriptor(descriptor: int, size: int, uri: str, file: str, at: str) -> bytes:
    """The first ``size`` bytes of an open regular file (fewer if it shrank meanwhile): one
    piece of at most ``_PIECE`` bytes is the bytes object itself, no copy."""
    pieces, left = [], size
    try:
        while left:
            piece = os.read(descriptor, min(left, _PIECE))
            if not piece:
                break
            pieces.append(piece)
            left -= len(piece)
    except OSError as exc:
        raise InputError(f'"{_shown(uri)}" is unreadable ({exc.strerror or exc})', file=file,
                         where=at, fix=_KEEP) from None
    return pieces[0] if len(pieces) == 1 else b"".join(pieces)
