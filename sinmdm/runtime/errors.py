"""User-facing errors: the CLI prints them as one line and exits with status 2."""

from __future__ import annotations


class SinMDMError(Exception):
    """An error caused by the user's input (a file, an option), not a bug."""


class BVHError(SinMDMError):
    """A malformed BVH file; names the file, the line and what was expected."""

    def __init__(self, path: str, line: int | None, message: str):
        self.path = str(path)
        self.line = line
        self.message = message
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")


class ModelError(SinMDMError):
    """A model file that is damaged, foreign, or from another version or skeleton."""
