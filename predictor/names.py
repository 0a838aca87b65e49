"""Messages for names a user can misspell: a registry's unknown name gets the closest valid one ("did you mean",
difflib) and the list of valid names; an OS error becomes one line naming the flag and the path.

A copy of `crowdsim.names` (the packages do not import each other; `envs` uses crowdsim's).
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable
from pathlib import Path


def closest(name: str, valid: Iterable[str]) -> str | None:
    """The valid name closest to `name`, case ignored: the first that `name` abbreviates, else the most similar
    (difflib ratio >= 0.6); None when none is that close."""
    by_lower = {str(v).lower(): str(v) for v in valid}
    key = str(name).lower()
    found = [v for v in by_lower if key and v.startswith(key)] or \
        difflib.get_close_matches(key, list(by_lower), n=1, cutoff=0.6)
    return by_lower[found[0]] if found else None


def did_you_mean(name: str, valid: Iterable[str]) -> str:
    """" did you mean 'X'?" for the closest valid name, "" when none is close."""
    found = closest(name, valid)
    return f" did you mean {found!r}?" if found else ""


def unknown_name(kind: str, name: str, valid: Iterable[str], label: str = "valid names") -> str:
    """"unknown KIND 'NAME'; did you mean 'X'? valid names: A, B" (the question only when one is close)."""
    valid = [str(v) for v in valid]
    return f"unknown {kind} {name!r};{did_you_mean(name, valid)} {label}: {', '.join(valid)}"


def os_error_line(exc: OSError, flags: dict[str, object]) -> str:
    """One line for an OS error that names the flag whose value is the path at fault (`flags`: flag -> value, a
    path or a list of them): "--replay-file nope.txt: no such file or directory" for Python's own errors, and
    "--data: MESSAGE" for a message that names a path-valued flag's value; else the message itself."""
    message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    paths = {flag: [v for v in (value if isinstance(value, list | tuple) else [value]) if isinstance(v, Path)]
             for flag, value in flags.items()}
    for flag, values in paths.items():
        if exc.filename is not None and any(str(v) == str(exc.filename) for v in values):
            return f"{flag} {exc.filename}: {(exc.strerror or message).lower()}"
    if exc.filename is not None:
        return f"{exc.filename}: {(exc.strerror or message).lower()}"
    flag = next((f for f, values in paths.items() if any(str(v) in message for v in values)), None)
    return message if flag is None or message.startswith(flag) else f"{flag}: {message}"


def flag_values(args: object) -> dict[str, object]:
    """--flag -> value of an argparse namespace (dest `replay_file` is flag `--replay-file`)."""
    return {f"--{dest.replace('_', '-')}": value for dest, value in vars(args).items()}


def parser_hint(message: str, options: Iterable[str], typed: Iterable[str] = ()) -> str:
    """argparse's error `message` with " did you mean X?" added: for an invalid choice, the closest of the choices it
    lists; for an unrecognized option, the closest of `options` (every --flag of the command line); for a missing
    required option, the closest to a --flag among the `typed` arguments that is none of `options`."""
    options = list(options)
    choice = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
    unknown = re.match(r"unrecognized arguments: (--[^\s=]+)", message)
    required = re.match(r"the following arguments are required: (.*)", message)
    hint = ""
    if choice:
        hint = did_you_mean(choice[1], re.findall(r"'([^']*)'", choice[2]))
    elif unknown:
        hint = did_you_mean(unknown[1], options)
    elif required:
        strays = [t.split("=")[0] for t in typed if t.startswith("--") and t.split("=")[0] not in options]
        hint = next((h for s in strays if (h := did_you_mean(s, required[1].split(", ")))), "")
    return f"{message};{hint}" if hint else message


def long_options(parser: object) -> list[str]:
    """Every --flag of an argparse parser and of its subcommands."""
    out: set[str] = set()
    for action in getattr(parser, "_actions", []):
        out.update(s for s in action.option_strings if s.startswith("--"))
        if isinstance(action.choices, dict):  # the subcommands' parsers
            for sub in action.choices.values():
                out.update(long_options(sub))
    return sorted(out)
