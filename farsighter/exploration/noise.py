"""Action noise for the continuous agents without a posterior (naf, knaf): Gaussian, or an
Ornstein-Uhlenbeck process per environment that starts afresh with each episode
(``NAFConfig.noise``). The noise is in units of half the action range; its random numbers come
from the generator it is handed (the agent's, which the agent saves)."""

from __future__ import annotations

import numpy as np

from farsighter.config import Config


class ActionNoise:
    """Gaussian (``noise_std``) or OU (``ou_theta``, ``noise_std``) noise of ``action_dim``."""

    def __init__(self, cfg: Config, action_dim: int, rng: np.random.Generator) -> None:
        self.naf = cfg.naf
        self.action_dim = action_dim
        self.rng = rng
        self.ou_EA = np.zeros((cfg.num_envs, action_dim), dtype=np.float64)

    def __call__(self, n: int) -> np.ndarray:
        """The noise of ``n`` environments' actions, (n, action_dim)."""
        naf = self.naf
        if naf.noise == "gaussian":
            return self.rng.normal(0.0, naf.noise_std, size=(n, self.action_dim))
        if self.ou_EA.shape[0] != n:
            self.ou_EA = np.zeros((n, self.action_dim))
        self.ou_EA += -naf.ou_theta * self.ou_EA + naf.noise_std * self.rng.normal(
            size=self.ou_EA.shape
        )
        return self.ou_EA.copy()

    def ended(self, done_E: np.ndarray) -> None:
        """A new episode starts the OU process afresh."""
        if self.ou_EA.shape[0] == len(done_E):
            self.ou_EA[done_E] = 0.0
