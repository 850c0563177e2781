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


class OptionError(SinMDMError):
    """A bad value for a named option. `option` is the API's name (e.g. "source_fps");
    the CLI renders it as its flag (--source-fps)."""

    def __init__(self, option: str, message: str):
        self.option = option
        self.message = message
        super().__init__(f"{option}: {message}")
