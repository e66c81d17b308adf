"""Any bsuite experiment (Osband et al. 2020, "Behaviour Suite for Reinforcement Learning") as a
Gymnasium environment: ``bsuite/<experiment>-<index>`` names bsuite's id ``<experiment>/<index>``
(``bsuite/cartpole_swingup-0``, ``bsuite/umbrella_length-5``, ``bsuite/catch_noise-3``),
registered on first use and built from ``bsuite.sweep.SETTINGS`` by bsuite's own loader, so the
dynamics, rewards and settings are bsuite's.

- Observations are bsuite's array flattened to float32; actions are ``Discrete``.
- An episode that ends with discount 0 is terminated, one that ends otherwise truncated (a
  k-step target bootstraps from it).
- ``reset(seed=s)`` builds the environment anew with ``seed=s`` where bsuite's constructor takes a
  seed the setting leaves open, and otherwise reseeds the environment's own generator where it
  has one (the stochastic deep sea's noise), so that a run is a function of its seed; a setting's
  ``mapping_seed`` (which arm pays, which chain has the bonus) is the setting's, as in bsuite's
  sweep.
- Constructor arguments (``--env-kwargs chain_length=5``) replace the setting's.
- The mnist experiments are refused: bsuite downloads MNIST when it makes them.
"""

from __future__ import annotations

import inspect
import re
from collections.abc import Callable
from typing import Any

import gymnasium
import numpy as np
from numpy.typing import NDArray

from farsighter.envs.deep_sea import BSUITE_EXTRA

__all__ = ["BSUITE_ID", "BsuiteEnv", "register_bsuite"]

BSUITE_ID = re.compile(r"^bsuite/([a-z_]+)-(\d+)$")


def _constructor(experiment: str) -> Callable[..., Any]:
    try:
        from bsuite.bsuite import EXPERIMENT_NAME_TO_ENVIRONMENT
    except ImportError:
        raise ImportError(f"bsuite environments need the bsuite package; {BSUITE_EXTRA}") from None
    if experiment not in EXPERIMENT_NAME_TO_ENVIRONMENT:
        names = ", ".join(sorted(EXPERIMENT_NAME_TO_ENVIRONMENT))
        raise ValueError(f"bsuite has no experiment '{experiment}' (it has {names})")
    if experiment.startswith("mnist"):  # bsuite fetches MNIST from the internet when it loads
        raise ValueError(f"bsuite's {experiment} downloads MNIST when made; not supported")
    return EXPERIMENT_NAME_TO_ENVIRONMENT[experiment]  # type: ignore[no-any-return]


def _setting(experiment: str, index: int) -> dict[str, Any]:
    from bsuite import sweep

    key = f"{experiment}{sweep.SEPARATOR}{index}"
    if key not in sweep.SETTINGS:
        count = sum(k.startswith(experiment + sweep.SEPARATOR) for k in sweep.SETTINGS)
        raise ValueError(f"bsuite's {experiment} has settings 0 to {count - 1} (got {index})")
    return dict(sweep.SETTINGS[key])


class BsuiteEnv(gymnasium.Env[NDArray[np.float32], np.int64]):
    """bsuite experiment ``experiment``, setting ``index`` (module docstring); ``overrides``
    replace the setting's constructor arguments."""

    metadata = {"render_modes": []}

    def __init__(self, experiment: str, index: int = 0, **overrides: Any) -> None:
        self._make = _constructor(experiment)
        self._kwargs = {**_setting(experiment, index), **overrides}
        self._seeded = "seed" in inspect.signature(self._make).parameters and (
            self._kwargs.get("seed") is None
        )
        self._env = self._make(**self._kwargs)
        spec = self._env.observation_spec()
        low, high = getattr(spec, "minimum", -np.inf), getattr(spec, "maximum", np.inf)
        size = int(np.prod(spec.shape))
        self.observation_space = gymnasium.spaces.Box(
            np.broadcast_to(np.asarray(low, np.float32), spec.shape).ravel(),
            np.broadcast_to(np.asarray(high, np.float32), spec.shape).ravel(),
            (size,),
            np.float32,
        )
        self.action_space = gymnasium.spaces.Discrete(int(self._env.action_spec().num_values))

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None and self._seeded:
            self._env = self._make(**{**self._kwargs, "seed": seed})
        elif seed is not None and isinstance(
            getattr(self._env, "_rng", None), np.random.RandomState
        ):
            self._env._rng = np.random.RandomState(seed)  # noqa: SLF001  (stochastic deep sea)
        step = self._env.reset()
        return np.asarray(step.observation, np.float32).ravel(), {}

    def step(self, action: Any) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        step = self._env.step(int(action))
        obs = np.asarray(step.observation, np.float32).ravel()
        ended = bool(step.last())
        terminated = ended and float(step.discount) == 0.0
        return obs, float(step.reward), terminated, ended and not terminated, {}


def register_bsuite(env_id: str) -> bool:
    """Register ``env_id`` if it names a bsuite experiment (``bsuite/<experiment>-<index>``);
    True if it does."""
    match = BSUITE_ID.match(env_id)
    if match is None:
        return False
    if env_id not in gymnasium.registry:
        gymnasium.register(
            id=env_id,
            entry_point="farsighter.envs.bsuite_env:BsuiteEnv",
            kwargs={"experiment": match.group(1), "index": int(match.group(2))},
        )
    return True
