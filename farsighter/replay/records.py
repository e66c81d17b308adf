"""What passes into and out of the replay (:mod:`farsighter.replay.buffer`, which re-exports
them): :class:`VectorStep`, one step of E environments as the loop hands it to an agent;
:class:`Batch`, a minibatch of k-step transitions; :class:`Episode`, one whole episode."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class VectorStep:
    """One step of E environments, as the training loop hands it to an agent's ``observe``."""

    obs_E: np.ndarray
    """Observations the actions were chosen on, (E, *obs)."""
    action_E: np.ndarray
    """Actions taken, (E,) discrete or (E, A) continuous."""
    reward_E: np.ndarray
    """Rewards received, (E,)."""
    terminated_E: Any
    """True where the episode ended in a terminal state (no bootstrap), (E,)."""
    truncated_E: Any
    """True where the episode was cut by a time limit (bootstrap from its last state), (E,)."""
    final_obs_E: Any = None
    """The last observation of each environment whose episode ended at this step (else None),
    or None when no episode ended."""


@dataclass
class Batch:
    """A minibatch of k-step transitions (numpy; the agent moves it to its device)."""

    obs: Any
    """Start observations s_t (stacked for images): numpy, or a tensor on the replay's device
    when sampled with ``on_device``."""
    actions: np.ndarray
    """Actions a_t."""
    returns: np.ndarray
    """r^k = sum_j gamma^j r_{t+j}, float32."""
    bootstrap: np.ndarray
    """gamma^n, or 0 if the episode terminated inside the window, float32."""
    next_obs: Any
    """Bootstrap observations s_{t+n} (numpy, or on the device like ``obs``)."""
    steps: np.ndarray
    """n: transitions summed (k unless the episode ended first)."""
    env_index: np.ndarray
    """Stream (vectorised environment) of each sample."""
    index: np.ndarray
    """Logical row index of each start."""


@dataclass
class Episode:
    """One complete episode held in the replay: its transitions are the logical rows
    ``start .. start + length - 1`` of stream ``env`` and row ``start + length`` is its final row
    (the last observation), so state s_t is row ``start + t`` for t = 0..length."""

    env: int
    start: int
    length: int
    actions: np.ndarray
    """a_t, t = 0..length-1."""
    rewards: np.ndarray
    """r_t, t = 0..length-1 (float32)."""
    terminated: bool
    """The last step terminated the episode (no bootstrap); False for a time-limit truncation."""
