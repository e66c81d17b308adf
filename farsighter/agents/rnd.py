"""RND (Burda et al. 2018, "Exploration by random network distillation") on DDQN: ``rnd``
(1-step) and ``krnd`` (k-step returns), the RND and TD(K)+RND baselines of appendix 9.1.1.

* Acting: epsilon-greedy on Q, exactly as ddqn.py.
* Intrinsic reward of a state s: e(s) = mean_j (f_hat(x)_j - f(x)_j)^2, with f a fixed random
  network, f_hat the trained predictor (same torso, two more layers, as in the RND paper) and x
  the observation: flat vectors whitened by a running mean/std of every observed state and
  clipped to [-5, 5] (RND paper section 2.4), images scaled to [0, 1] by the CNN.
  Normalised: i(s) = e(s) / sigma_e, sigma_e a running std of all intrinsic rewards computed.
* Targets (Eq. 2 with k-step returns): for a window starting at s_t with n <= k steps,
      R = sum_{j<n} gamma^j (r_{t+j} + lambda i(s_{t+j+1})),
      y = R + gamma^n Q_target(s_{t+n}, argmax_a Q(s_{t+n}, a))   (no bootstrap at a terminal).
  Our choice: the intrinsic rewards of the window's next states s_{t+1..t+n} are computed when the
  minibatch is sampled, with the current predictor, not stored at collection: they decay as the
  predictor learns, and they enter the k-step sum with the same discounts and the same episode-end
  rules as the extrinsic rewards (the replay's window). The bonus is therefore episodic (it stops
  at terminals), where the RND paper keeps a separate non-episodic intrinsic value head.
* The predictor takes one Adam step per update on the minibatch's observations s_t.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from farsighter.agents.common import (
    Counters,
    RunningMeanStd,
    batch_tensors,
    build_seeded,
    greedy_actions,
    load_state,
    make_replay,
    obs_tensor,
    sample_minibatch,
    save_state,
    sync_target,
    updates_owed,
)
from farsighter.agents.ddqn import DoubleQLoss
from farsighter.agents.learner import Learner
from farsighter.agents.protocol import AgentFactory
from farsighter.config import Config
from farsighter.exploration import EpsilonGreedy
from farsighter.networks import QNetwork, make_torso
from farsighter.replay import Batch, VectorStep

STD_EPS = 1e-8


class RNDNetwork(nn.Module):
    """A torso (MLP or Nature CNN) and ``extra_layers`` hidden layers, then ``feature_dim`` outputs."""

    def __init__(
        self,
        obs_space: gym.spaces.Box,
        hidden_sizes: tuple[int, ...],
        feature_dim: int,
        extra_layers: int,
    ) -> None:
        super().__init__()
        self.torso = make_torso(obs_space, hidden_sizes)
        d = self.torso.out_dim
        layers: list[nn.Module] = []
        for _ in range(extra_layers):
            layers += [nn.Linear(d, d), nn.ReLU()]
        self.head = nn.Sequential(*layers, nn.Linear(d, feature_dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.torso(x))


class RNDAgent:
    """DDQN with a random-network-distillation bonus added to the reward (module docstring)."""

    def __init__(
        self,
        cfg: Config,
        obs_space: gym.spaces.Box,
        act_space: gym.spaces.Discrete,
        *,
        frame_stack: int,
        device: torch.device,
    ) -> None:
        self.cfg = cfg
        self.device = device
        self.num_actions = int(act_space.n)
        self.q = build_seeded(
            cfg.seed, lambda: QNetwork(obs_space, self.num_actions, cfg.hidden_sizes)
        ).to(device)
        # DDQN's loss on the returns with the bonus added (module docstring)
        self.loss = DoubleQLoss(self.q, cfg.loss)
        self.learner = Learner(self.loss, self.q.parameters(), cfg, device)
        r = cfg.rnd
        self.rnd_target = build_seeded(
            cfg.seed + 4, lambda: RNDNetwork(obs_space, cfg.hidden_sizes, r.feature_dim, 0)
        ).to(device)
        self.rnd_target.requires_grad_(False)
        # RND paper: the predictor is the target's architecture with two more layers.
        self.predictor = build_seeded(
            cfg.seed + 5, lambda: RNDNetwork(obs_space, cfg.hidden_sizes, r.feature_dim, 2)
        ).to(device)
        rnd_opt = torch.optim.Adam(self.predictor.parameters(), lr=r.lr, foreach=True)
        # the predictor's step, eager (no clipping): the bonus it gives is read on the host
        self.predictor_learner = Learner(
            self.predictor_loss,
            self.predictor.parameters(),
            cfg,
            device,
            optimizer=rnd_opt,
            max_grad_norm=0.0,
            eager=True,
        )
        shape = obs_space.shape
        assert shape is not None
        self.whiten = r.normalize_obs and len(shape) == 1
        self.obs_rms = RunningMeanStd(tuple(shape) if self.whiten else ())
        self.intrinsic_rms = RunningMeanStd()
        self.replay = make_replay(cfg, obs_space, frame_stack, seed=cfg.seed + 1, device=device)
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.explore = EpsilonGreedy(cfg, self.num_actions, self.rng)
        self.counters = Counters(k=cfg.k)
        self.stats = {"intrinsic_reward": float("nan"), "predictor_loss": float("nan")}

    # ------------------------------------------------------------------ acting
    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        """Epsilon-greedy actions for a batch of environments (greedy when not exploring)."""
        if not explore:
            return self.greedy(obs_E)
        return self.explore(global_step, lambda: self.greedy(obs_E), obs_E.shape[0])

    def greedy(self, obs_E: np.ndarray) -> np.ndarray:
        return greedy_actions(self.q, obs_E, self.device)

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Q(s, .) for a batch of states; no posterior, so no variance."""
        return self.q(obs_tensor(obs_B, self.device)).cpu().numpy(), None

    def observe(self, step: VectorStep) -> None:
        self.replay.add_step(step)
        if self.whiten:  # statistics of every visited state (RND paper section 2.4)
            self.obs_rms.update(np.asarray(step.obs_E))

    # ------------------------------------------------------------------ the bonus
    def _rnd_input(self, obs: torch.Tensor) -> torch.Tensor:
        if not self.whiten:
            return obs  # images: the CNN scales bytes to [0, 1]
        mean = torch.as_tensor(self.obs_rms.mean, dtype=torch.float32, device=self.device)
        std = torch.as_tensor(
            np.sqrt(self.obs_rms.var + STD_EPS), dtype=torch.float32, device=self.device
        )
        clip = self.cfg.rnd.obs_clip
        return ((obs.float() - mean) / std).clamp(-clip, clip)

    @torch.no_grad()
    def prediction_error(self, obs: torch.Tensor) -> torch.Tensor:
        """e(s) = mean_j (f_hat(x)_j - f(x)_j)^2, the unnormalised intrinsic reward, (B,)."""
        x = self._rnd_input(obs)
        return (self.predictor(x) - self.rnd_target(x)).pow(2).mean(dim=1)

    def normalize_intrinsic(self, e_N: np.ndarray) -> np.ndarray:
        """i = e / sigma_e, with sigma_e the running std of every intrinsic reward so far."""
        self.intrinsic_rms.update(e_N)
        return e_N / (float(self.intrinsic_rms.std) + STD_EPS)

    def predictor_loss(self, inputs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The distillation loss mean_j (f_hat(x)_j - f(x)_j)^2 on observations ``obs_B``."""
        x = self._rnd_input(inputs["obs_B"])
        return {"loss": (self.predictor(x) - self.rnd_target(x)).pow(2).mean()}

    def intrinsic_returns(self, batch: Batch) -> np.ndarray:
        """sum_{j<n} gamma^j i(s_{t+j+1}) for every window of the minibatch (float32, (B,))."""
        k = int(batch.steps.max())
        offsets_K = np.arange(1, k + 1)
        alive_BK = offsets_K[None, :] <= batch.steps[:, None]
        rows_BK = batch.index[:, None] + offsets_K[None, :]  # s_{t+j+1}; s_{t+n} may be final
        e_BK = np.broadcast_to(batch.env_index[:, None], rows_BK.shape)
        obs_N = self.replay.stacked_obs(e_BK[alive_BK], rows_BK[alive_BK])
        e_N = self.prediction_error(obs_tensor(obs_N, self.device)).cpu().numpy()
        i_BK = np.zeros(rows_BK.shape, dtype=np.float64)
        i_BK[alive_BK] = self.normalize_intrinsic(e_N)
        self.stats["intrinsic_reward"] = float(i_BK[alive_BK].mean())
        discounts_K = self.cfg.gamma ** np.arange(k, dtype=np.float64)
        return (i_BK * discounts_K).sum(axis=1).astype(np.float32)

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        metrics: dict[str, torch.Tensor] = {}
        for _ in range(updates_owed(self.counters, self.cfg, global_step)):
            metrics["td_loss"] = self.update()
        sync_target(
            self.counters, global_step, self.cfg.target_update_every, (self.q, self.loss.q_target)
        )
        return metrics

    def update(self) -> torch.Tensor:
        """One double-Q step on extrinsic + weighted intrinsic k-step returns, then one predictor
        step on the same minibatch; returns the TD loss."""
        cfg = self.cfg
        batch = sample_minibatch(self.replay, cfg, cfg.batch_size, self.counters.k)
        inputs = batch_tensors(batch, self.device).tensors()
        ri_B = torch.as_tensor(self.intrinsic_returns(batch), device=self.device)
        inputs["returns_B"] = inputs["returns_B"] + cfg.rnd.intrinsic_weight * ri_B
        loss = self.learner(inputs)["loss"]
        predictor = self.predictor_learner({"obs_B": inputs["obs_B"]})["loss"]
        self.stats["predictor_loss"] = float(predictor)
        return loss

    def diagnostics(self) -> dict[str, float]:
        return {
            "epsilon": self.explore.epsilon,
            "k": float(self.counters.k),
            "intrinsic_reward": self.stats["intrinsic_reward"],
            "intrinsic_std": float(self.intrinsic_rms.std),
            "predictor_loss": self.stats["predictor_loss"],
        }

    # ------------------------------------------------------------------ checkpoints
    SAVED = (
        "q",
        "q_target",
        "opt",
        "rnd_target",
        "predictor",
        "rnd_opt",
        "obs_rms",
        "intrinsic_rms",
        "rng",
        "epsilon",
        "stats",
        "counters",
    )

    SAVED_AT = {  # keys of the earlier layout
        "q_target": "loss.q_target",
        "opt": "learner",
        "rnd_opt": "predictor_learner",
        "epsilon": "explore.epsilon",
    }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        return save_state(self, self.SAVED, include_replay)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        load_state(self, self.SAVED, state)


AGENT: AgentFactory = RNDAgent  # the class farsighter.algorithms names; mypy checks the protocol
