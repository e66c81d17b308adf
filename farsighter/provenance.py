"""Which code made a result: the git commit of the running package (and whether its tree held
uncommitted changes), or the installed version where the package is not a git checkout."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def code_version() -> dict[str, Any]:
    """``{"commit": sha, "dirty": bool}`` of the checkout the package runs from, or
    ``{"version": "x.y.z"}`` when git or the checkout is missing."""
    from farsighter import __version__

    if not (ROOT / "pyproject.toml").exists():  # installed, not run from a checkout
        return {"version": __version__}
    try:
        sha = _git("rev-parse", "HEAD")
        changed = _git("status", "--porcelain", "--untracked-files=no", "--", "farsighter")
    except (OSError, subprocess.SubprocessError):
        return {"version": __version__}
    return {"commit": sha, "dirty": bool(changed), "version": __version__}


def _git(*args: str) -> str:
    out = subprocess.run(
        ["git", "-C", str(ROOT), *args], capture_output=True, text=True, timeout=20, check=True
    )
    return out.stdout.strip()
