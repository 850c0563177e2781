"""Shared CLI glue: one-line errors with exit status 2, JSON output, consoles."""

from __future__ import annotations

import json
import sys
from typing import Any, Callable

import typer
from rich.console import Console

from ..runtime.errors import SinMDMError

console = Console(stderr=True)
EXIT_USAGE = 2


def fail(message: str) -> None:
    """Print one line on stderr and exit with status 2."""
    sys.stderr.write(f"error: {message}\n")
    raise typer.Exit(EXIT_USAGE)


def print_json(data: Any) -> None:
    sys.stdout.write(json.dumps(data, indent=2, default=_jsonable) + "\n")


def _jsonable(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)


def run_app(app: typer.Typer) -> Callable[[], None]:
    """Wrap a typer app so user errors become one line on stderr and exit status 2."""

    def main() -> None:
        if sys.argv[1:] == ["--version"]:
            from .. import __version__

            sys.stdout.write(f"{app.info.name} {__version__}\n")
            return
        try:
            app(prog_name=app.info.name)
        except SinMDMError as exc:
            sys.stderr.write(f"error: {exc}\n")
            sys.exit(EXIT_USAGE)
        except MemoryError:
            sys.stderr.write("error: out of memory\n")
            sys.exit(EXIT_USAGE)
        except KeyboardInterrupt:
            sys.stderr.write("interrupted\n")
            sys.exit(130)

    return main


RootOption = typer.Option(None, "--root", help="The joint that carries the character through the world (default: detected).")
UpOption = typer.Option("auto", "--up", help="Up axis of the file: y, z or auto (detected from where the feet rest).")
