"""What one vector step's results say: the episodes that ended, with their last observations,
and whether its rewards and observations are finite (re-exported by :mod:`farsighter.session`;
the training loops read these after every step)."""

from __future__ import annotations

from typing import Any

import numpy as np

from farsighter.errors import EnvError


def final_observations(info: dict[str, Any], num_envs: int) -> list[Any] | None:
    """The last observation of each environment whose episode ended at this step (else None)."""
    if "final_obs" not in info:
        return None
    mask = info["_final_obs"]
    return [info["final_obs"][i] if mask[i] else None for i in range(num_envs)]


def check_transition(
    env_id: str, step: int, rewards: np.ndarray, obs: Any, final_obs: list[Any] | None
) -> None:
    """Refuse, with one line naming the environment and ``step``, a vector step whose rewards or
    (floating-point) observations hold NaN or infinity: the environment's fault, which would
    otherwise reach the updates and read as diverged training. One ``isfinite`` pass over the
    rewards and one over the observations (none for integer images); the last observations of
    the episodes that ended (``final_obs``) are checked too."""
    floats = isinstance(obs, np.ndarray) and obs.dtype.kind == "f"
    if np.isfinite(rewards).all() and not final_obs and (not floats or np.isfinite(obs).all()):
        return
    found = _non_finite(rewards)
    what = "a reward of"
    if found is None:
        what = "an observation holding"
        found = _non_finite(obs)
        for i, last in enumerate(final_obs or ()):
            if found is None and last is not None:
                at_last = _non_finite(np.asarray(last)[None])
                found = None if at_last is None else (i, at_last[1])
    if found is not None:
        raise EnvError(
            f"the environment {env_id} returned {what} {found[1]} at step {step:,} "
            f"(environment {found[0]}); a NaN or infinite reward or observation is the "
            "environment's to fix"
        )


def _non_finite(values: Any) -> tuple[int, float] | None:
    """(row, value) of the first non-finite entry of a floating-point batch (rows: the
    environments); None when every entry is finite or the batch holds no floats."""
    batch = np.asarray(values)
    if batch.dtype.kind != "f" or np.isfinite(batch).all():
        return None
    rows = batch.reshape(len(batch), -1)
    row = int(np.flatnonzero(~np.isfinite(rows).all(axis=1))[0])
    return row, float(rows[row][~np.isfinite(rows[row])][0])


def finished_episodes(info: dict[str, Any]) -> list[tuple[float, int, float | None]]:
    """(return, length, ``info["is_success"]`` or None) of the episodes that ended this step."""
    final = info.get("final_info")
    if not final or "episode" not in final:
        return []
    ep, has_success = final["episode"], final.get("_is_success")
    return [
        (
            float(ep["r"][i]),
            int(ep["l"][i]),
            float(final["is_success"][i]) if has_success is not None and has_success[i] else None,
        )
        for i in np.flatnonzero(final["_episode"])
    ]
