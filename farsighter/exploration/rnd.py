"""RND's bonus (Burda et al. 2018, "Exploration by random network distillation") as an
exploration object: the rnd and krnd agents add it to the reward (farsighter.agents.rnd).

* Intrinsic reward of a state s: e(s) = mean_j (f_hat(x)_j - f(x)_j)^2, with f a fixed random
  network, f_hat the trained predictor (same torso, two more layers, as in the RND paper) and x
  the observation: flat vectors whitened by a running mean/std of every observed state and
  clipped to [-obs_clip, obs_clip] (RND paper section 2.4: 5), images scaled to [0, 1] by the
  CNN. Normalised: i(s) = e(s) / sigma_e, sigma_e a running std of all intrinsic rewards computed.
* For a k-step window starting at s_t with n <= k steps, the bonus return is
  sum_{j<n} gamma^j i(s_{t+j+1}), computed when the minibatch is sampled, with the current
  predictor (so it decays as the predictor learns), with the same discounts and episode-end
  rules as the extrinsic rewards (the replay's window): an episodic bonus, where the RND paper
  keeps a separate non-episodic intrinsic value head.
* The predictor takes one Adam step per update on the minibatch's observations s_t.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from farsighter.config import Config
from farsighter.ops.running import RunningMeanStd
from farsighter.replay import Batch, ReplayBuffer
from farsighter.replay.buffer import host_to_device

STD_EPS = 1e-8


class RNDBonus:
    """The random-network-distillation bonus of one agent (module docstring)."""

    def __init__(
        self,
        cfg: Config,
        target: nn.Module,
        predictor: nn.Module,
        obs_shape: tuple[int, ...],
        device: torch.device,
    ) -> None:
        self.rnd, self.gamma, self.device = cfg.rnd, cfg.gamma, device
        self.rnd_target = target.requires_grad_(False)
        self.predictor = predictor
        self.rnd_opt = torch.optim.Adam(predictor.parameters(), lr=cfg.rnd.lr, foreach=True)
        self.whiten = cfg.rnd.normalize_obs and len(obs_shape) == 1
        self.obs_rms = RunningMeanStd(tuple(obs_shape) if self.whiten else ())
        self.intrinsic_rms = RunningMeanStd()
        self.stats = {"intrinsic_reward": float("nan"), "predictor_loss": float("nan")}

    def observe(self, obs_E: np.ndarray) -> None:
        """Statistics of every visited state (RND paper section 2.4)."""
        if self.whiten:
            self.obs_rms.update(np.asarray(obs_E))

    def _input(self, obs: torch.Tensor) -> torch.Tensor:
        if not self.whiten:
            return obs  # images: the CNN scales bytes to [0, 1]
        mean = torch.as_tensor(self.obs_rms.mean, dtype=torch.float32, device=self.device)
        std = torch.as_tensor(
            np.sqrt(self.obs_rms.var + STD_EPS), dtype=torch.float32, device=self.device
        )
        clip = self.rnd.obs_clip
        return ((obs.float() - mean) / std).clamp(-clip, clip)

    @torch.no_grad()
    def prediction_error(self, obs: torch.Tensor) -> torch.Tensor:
        """e(s) = mean_j (f_hat(x)_j - f(x)_j)^2, the unnormalised intrinsic reward, (B,)."""
        x = self._input(obs)
        return (self.predictor(x) - self.rnd_target(x)).pow(2).mean(dim=1)

    def normalize(self, e_N: np.ndarray) -> np.ndarray:
        """i = e / sigma_e, with sigma_e the running std of every intrinsic reward so far."""
        self.intrinsic_rms.update(e_N)
        return e_N / (float(self.intrinsic_rms.std) + STD_EPS)

    def returns(self, batch: Batch, replay: ReplayBuffer) -> np.ndarray:
        """sum_{j<n} gamma^j i(s_{t+j+1}) for every window of the minibatch (float32, (B,))."""
        k = int(batch.steps.max())
        offsets_K = np.arange(1, k + 1)
        alive_BK = offsets_K[None, :] <= batch.steps[:, None]
        rows_BK = batch.index[:, None] + offsets_K[None, :]  # s_{t+j+1}; s_{t+n} may be final
        e_BK = np.broadcast_to(batch.env_index[:, None], rows_BK.shape)
        obs_N = replay.stacked_obs(e_BK[alive_BK], rows_BK[alive_BK])
        e_N = self.prediction_error(host_to_device(torch.as_tensor(obs_N), self.device))
        i_BK = np.zeros(rows_BK.shape, dtype=np.float64)
        i_BK[alive_BK] = self.normalize(e_N.cpu().numpy())
        self.stats["intrinsic_reward"] = float(i_BK[alive_BK].mean())
        discounts_K = self.gamma ** np.arange(k, dtype=np.float64)
        return (i_BK * discounts_K).sum(axis=1).astype(np.float32)

    def train(self, obs_B: torch.Tensor) -> float:
        """One Adam step of f_hat towards f on these observations; returns the loss."""
        x = self._input(obs_B)
        loss = (self.predictor(x) - self.rnd_target(x)).pow(2).mean()
        self.rnd_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.rnd_opt.step()
        self.stats["predictor_loss"] = float(loss.detach())
        return self.stats["predictor_loss"]
