"""Each config field's type, and a value checked against it.

A config is built from Python keywords (``make_config``), sweep files and JSON as well as the
command line; only tyro reads types for itself. :func:`field_value` is what the others share: a
value is accepted as its field's type or refused with what the field takes, after the
conversions that lose nothing (a list for a tuple, ``1e5`` for an integer, YAML 1.1's string
``"1e-4"`` for a number).
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import typing
from typing import Any, Literal

from farsighter.config.fields import Config

OPEN_CHOICES = frozenset({"blr.redraw"})
"""Fields of named choices that a registry extends (``farsighter.exploration.SCHEDULES``), so
that a name beyond the field's own is the registry's to judge."""


@functools.cache
def leaf_fields() -> tuple[dict[str, Any], dict[str, Any]]:
    """Every leaf field of :class:`Config`, dotted for nested ones (``blr.prior_std``), with its
    type; and the nested sections (``blr``, ``runtime``, ...) with their dataclasses."""
    leaves: dict[str, Any] = {}
    sections: dict[str, Any] = {}
    hints = typing.get_type_hints(Config)
    for f in dataclasses.fields(Config):
        hint = hints[f.name]
        if dataclasses.is_dataclass(hint):
            sections[f.name] = hint
            sub_hints = typing.get_type_hints(hint)
            for sub in dataclasses.fields(hint):
                leaves[f"{f.name}.{sub.name}"] = sub_hints[sub.name]
        else:
            leaves[f.name] = hint
    return leaves, sections


def field_value(
    key: str, value: Any, convert: bool = True, choices: bool = True
) -> tuple[Any, str]:
    """``(value, "")`` with ``value`` as the dotted field ``key`` takes it, or ``(value, what the
    field takes)`` when it cannot be read as that. ``convert=False``: the value as it is (the
    check of a built config), no conversion. ``choices=False``: a field of named choices takes
    any string, for the section's own check to judge (a registry may extend its choices, as
    :data:`farsighter.exploration.SCHEDULES` does ``blr.redraw``'s)."""
    hint = leaf_fields()[0][key]
    origin = typing.get_origin(hint)
    if convert and isinstance(value, float) and value.is_integer() and hint is int:
        value = int(value)  # 1e5
    if convert and isinstance(value, str) and hint is float:
        try:  # YAML 1.1 reads 1e-4 (no dot) as a string
            value = float(value)
        except ValueError:
            pass
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is bool:
        return value, "" if isinstance(value, bool) else "true or false"
    if hint is int:
        return value, "" if number and isinstance(value, int) else "an integer"
    if hint is float:
        return value, "" if number else "a number"
    if hint is str:
        return value, "" if isinstance(value, str) else "a string"
    if origin is Literal and not choices:
        return value, "" if isinstance(value, str) else "a string"
    if origin is Literal:
        named = typing.get_args(hint)
        return value, "" if value in named else "one of " + ", ".join(map(str, named))
    if origin is tuple and typing.get_args(hint)[0] is str:  # env_kwargs: NAME=VALUE items
        if convert and isinstance(value, dict):  # {"is_slippery": False}
            if not all(_literal(v) for v in value.values()):
                return value, "a dict of Python literals (numbers, strings, bools, lists, None)"
            value = tuple(f"{name}={v!r}" for name, v in value.items())
        kinds = (list, tuple) if convert else (tuple,)
        if not isinstance(value, kinds) or not all(isinstance(v, str) for v in value):
            return value, "a list of strings" + (" or a dict" if convert else "")
        return tuple(value), ""
    if origin is tuple and typing.get_args(hint)[0] is int:  # hidden sizes
        kinds = (list, tuple) if convert else (tuple,)
        items = list(value) if isinstance(value, kinds) else None
        if items is not None and convert:
            items = [int(v) if isinstance(v, float) and v.is_integer() else v for v in items]
        if items is None or any(not isinstance(v, int) or isinstance(v, bool) for v in items):
            return value, "a list of integers" if convert else "a tuple of integers"
        return tuple(items), ""
    return value, ""


def _literal(value: Any) -> bool:
    """Whether ``repr(value)`` reads back as ``value`` (``ast.literal_eval``)."""
    try:
        return bool(ast.literal_eval(repr(value)) == value)
    except (ValueError, SyntaxError):
        return False
