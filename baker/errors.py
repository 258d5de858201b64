"""One exception family for everything the user can get wrong.

The library raises these where the problem is known; the command line renders them once, as one or
two lines naming the file, the glTF object (e.g. ``meshes[3].primitives[0].attributes.POSITION``)
and what to do. Anything else that escapes is a bug in baker.
"""

from __future__ import annotations


class BakerError(Exception):
    """A problem with the user's input or settings, with a message meant for people.

    ``file`` is the path of the input or output concerned, ``where`` the glTF JSON path of the
    object (empty when the problem is not tied to one) and ``fix`` what the user can do.
    """

    def __init__(self, message: str, *, file: str = "", where: str = "", fix: str = ""):
        super().__init__(message)
        self.message = message
        self.file = str(file)
        self.where = where
        self.fix = fix

    def __str__(self) -> str:
        head = ": ".join(part for part in (self.file, self.where) if part)
        text = f"{head}: {self.message}" if head else self.message
        return f"{text}\n  fix: {self.fix}" if self.fix else text


class InputError(BakerError):
    """The glTF file cannot be read or holds data baker cannot use."""


class SettingsError(BakerError):
    """A setting is out of range or cannot be met for this scene."""


class OutputError(BakerError):
    """The output cannot be written where the user asked."""
