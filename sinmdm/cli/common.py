"""Shared CLI glue: one-line errors with exit status 2, JSON output, consoles."""

from __future__ import annotations

import json
import os
import sys
from typing import Any, Callable

import typer
from rich.console import Console
from typer.exceptions import TyperException

from ..runtime.errors import OptionError, SinMDMError

EXIT_USAGE = 2
EXIT_INTERNAL = 1
EXIT_INTERRUPTED = 130
DEBUG_FLAG = "--debug"
DEBUG_ENV = "SINMDM_DEBUG"
# The runtime names options as the Python API does; these flags are spelled otherwise.
FLAGS = {"frame_range": "--frames", "keyframes": "--frames", "fmt": "--format", "as_json": "--json",
         "target": "TARGET"}


def _console() -> Console:
    """Messages on stderr; off a terminal (a pipe, a log) lines are never wrapped."""
    terminal = Console(stderr=True, soft_wrap=True)
    return terminal if terminal.is_terminal else Console(stderr=True, soft_wrap=True, width=10_000)


console = _console()


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


def flag(option: str) -> str:
    """The CLI flag of an API option name ("source_fps" -> "--source-fps")."""
    return FLAGS.get(option, "--" + option.replace("_", "-"))


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _user_error(exc: SinMDMError) -> str:
    return f"{flag(exc.option)}: {exc.message}" if isinstance(exc, OptionError) else str(exc)


def _debug_requested() -> bool:
    """A leading --debug (removed from the arguments) or SINMDM_DEBUG=1: tracebacks are shown."""
    if sys.argv[1:2] == [DEBUG_FLAG]:
        del sys.argv[1]
        return True
    return os.environ.get(DEBUG_ENV, "") not in ("", "0")


def run_app(app: typer.Typer) -> Callable[[], None]:
    """Wrap a typer app so user errors become one line on stderr with exit status 2, and
    anything unexpected one line with exit status 1 (the traceback with --debug)."""

    def main() -> None:
        debug = _debug_requested()
        if sys.argv[1:] == ["--version"]:
            from .. import __version__

            sys.stdout.write(f"{app.info.name} {__version__}\n")
            return
        try:
            status = app(prog_name=app.info.name, standalone_mode=False)
        except TyperException as exc:  # a usage error: bad or missing option, unknown command
            if type(exc).__name__ != "NoArgsIsHelpError":  # (as typer checks it) whose help is printed
                sys.stderr.write(f"error: {_one_line(exc.format_message())}\n")
            sys.exit(exc.exit_code)
        except SinMDMError as exc:
            sys.stderr.write(f"error: {_one_line(_user_error(exc))}\n")
            sys.exit(EXIT_USAGE)
        except MemoryError:
            sys.stderr.write("error: out of memory\n")
            sys.exit(EXIT_USAGE)
        except (KeyboardInterrupt, typer.Abort):
            sys.stderr.write("interrupted\n")
            sys.exit(EXIT_INTERRUPTED)
        except Exception as exc:
            if debug:
                raise
            sys.stderr.write(f"internal error: {type(exc).__name__}: {_one_line(exc)} "
                             f"(run with {DEBUG_FLAG} for the traceback)\n")
            sys.exit(EXIT_INTERNAL)
        if status == EXIT_INTERRUPTED:  # typer turns KeyboardInterrupt into this status
            sys.stderr.write("interrupted\n")
        sys.exit(status if isinstance(status, int) else 0)

    return main


RootOption = typer.Option(None, "--root", help="The joint that carries the character through the world (default: detected).")
UpOption = typer.Option("auto", "--up", help="Up axis of the file: y, z or auto (detected from where the feet rest).")
