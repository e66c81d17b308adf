"""Sweeps: a grid of training runs described in a TOML or YAML file.

:func:`load_spec` reads a sweep file, checks it and expands its grid into :class:`Trial` s (the
file format is documented in :mod:`farsighter.sweep.spec`).
"""

from farsighter.sweep.spec import (
    Resources,
    SweepError,
    SweepSpec,
    Trial,
    load_spec,
    parse_spec,
)

__all__ = ["Resources", "SweepError", "SweepSpec", "Trial", "load_spec", "parse_spec"]
