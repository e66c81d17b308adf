"""Every command's flags through tyro, its parse errors as one line.

tyro answers an unknown flag, a bad value or a missing one with a framed message of several
lines and exit 2. :func:`parse_flags` raises that message as one :class:`ConfigError` line instead
(what was wrong, what is accepted, the flag it may have meant), which the CLI prints as
``farsighter: error: ...`` with exit 2, as it does every other bad input. Integer flags take
integral scientific notation as well (``--total-steps 1e6``).
"""

from __future__ import annotations

import contextlib
import io
import math
import sys
from collections.abc import Sequence
from typing import Any, TypeVar

import tyro
from tyro.constructors import ConstructorRegistry, PrimitiveConstructorSpec, PrimitiveTypeInfo

from farsighter.errors import ConfigError

T = TypeVar("T")
INTEGERS = ConstructorRegistry()
"""Integer flags also read as integral scientific notation (``--total-steps 1e6``)."""


def read_int(text: str) -> int:
    """``"100000"`` or ``"1e5"`` as 100000; anything else (``"1.5"``, ``"many"``) refused."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value.is_integer():
        raise ValueError(f"{text!r} is not an integer")
    return int(value)


@INTEGERS.primitive_rule
def _integers(info: PrimitiveTypeInfo) -> PrimitiveConstructorSpec[int] | None:
    if info.type is not int:
        return None
    return PrimitiveConstructorSpec(
        nargs=1,
        metavar="INT",
        instance_from_str=lambda args: read_int(args[0]),
        is_instance=lambda x: isinstance(x, int) and not isinstance(x, bool),
        str_from_instance=lambda x: [str(x)],
    )


def parse_flags(cls: type[T], argv: Sequence[str], prog: str, **kwargs: Any) -> Any:
    """``tyro.cli(cls, args=argv, prog=prog, **kwargs)`` (its value, a tuple with
    ``return_unknown_args``); a parse error raises :class:`ConfigError` with tyro's message on one
    line. ``--help`` prints as tyro prints it."""
    args = list(argv)
    if "-h" in args or "--help" in args:
        return tyro.cli(cls, args=args, prog=prog, registry=INTEGERS, **kwargs)
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            value = tyro.cli(cls, args=args, prog=prog, registry=INTEGERS, **kwargs)
    except SystemExit as exc:
        if exc.code in (0, None):
            raise
        raise ConfigError(
            bool_value_hint(args, captured.getvalue(), prog) or one_line(captured.getvalue(), prog)
        ) from None
    sys.stderr.write(captured.getvalue())  # a warning of a parse that succeeded
    return value


def bool_value_hint(args: Sequence[str], message: str, prog: str) -> str | None:
    """For a parse that failed on a switch given a value (``--progress False``: tyro's
    ``message`` says the value was not recognised): the line that says how switches are
    written; None otherwise."""
    listed = [line for line in message.splitlines() if "Unrecognized options:" in line]
    if not listed:
        return None
    unknown = listed[0].split("Unrecognized options:", 1)[1].strip(" │").replace(",", " ").split()
    pairs = [tuple(a.split("=", 1)) for a in args if a.startswith("--") and "=" in a]
    pairs += [(a, b) for a, b in zip(args, args[1:], strict=False) if "=" not in a]
    for flag, value in pairs:
        if (
            flag.startswith("--")
            and value.lower() in ("true", "false")
            and value in unknown
            and flag not in unknown
        ):
            section, _, name = flag[2:].rpartition(".")
            off = f"--{section + '.' if section else ''}no-{name}"
            return (
                f"{flag} takes no value (got {flag} {value}): write {flag} to turn it on or "
                f"{off} to turn it off; {prog} --help lists the flags"
            )
    return None


def one_line(message: str, prog: str) -> str:
    """tyro's framed error message as one line: its first section, the accepted form of the
    flag a value was refused for, the flags it suggests, and where the flags are listed."""
    sections: list[list[str]] = []
    for raw in message.splitlines():
        line = raw.strip().strip("│").strip()
        # a section starts below a rule, or below the frame's top, which holds the title (in
        # plain text the title stands above the first rule)
        if line.startswith("╭") or (line and set(line) <= set("-─")):
            sections.append([])
        elif line and sections and not line.startswith("╰"):
            sections[-1].append(line)
    if not sections or not sections[0]:
        return f"cannot read the command line ({' '.join(message.split())[:200]})"
    first = sections[0]
    if first[0].startswith("Missing from") and len(first) > 1:  # a required argument
        first = [f"missing {first[1]}:", *first[2:]]
    text = " ".join(first).rstrip(".")
    for section in (s for s in sections[1:] if s):
        head, rest = section[0].rstrip(":"), section[1:]
        flags = [line.split()[0] for line in rest if line.startswith("-")]
        if head == "Argument helptext" and rest:
            text += f" (expected {' '.join(rest[0].split()[:2])})"
        elif head == "Perhaps you meant" and flags:
            text += f"; did you mean {' or '.join(dict.fromkeys(flags))}?"
    return f"{text}; {prog} --help lists the flags"
