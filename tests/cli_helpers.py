"""Helpers shared by the tests that drive a command line in-process or as a real process."""

from __future__ import annotations

import signal
from collections.abc import Callable


def run_cli(main: Callable[[list[str]], int], args: list[str], capsys) -> tuple[int, str]:
    """(exit code, stderr) of `main(args)`, whether argparse exits or main returns."""
    try:
        code = main(args)
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr().err


def terminal_sigint() -> None:
    """In a child process (`preexec_fn`): Ctrl-C as in a terminal, even when the test runs where SIGINT is ignored
    (a shell's background job), which the child would inherit."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
