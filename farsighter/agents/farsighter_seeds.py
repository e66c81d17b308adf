"""Farsighter and BDQN for S seeds at once: :class:`farsighter.agents.farsighter.FarsighterAgent`'s
math with the torsos stacked along a seed axis (:mod:`farsighter.stacked`), so that one forward
pass gives every seed's features and one backward pass updates every seed's torso.

What is per seed stays per seed and is the agent alone's own code: each seed's posterior (a
:class:`~farsighter.ops.blr.BLRHead`), its Thompson draws and redraw rule
(:class:`~farsighter.exploration.ThompsonExploration`), its generators (replay: seed + 1, numpy:
seed + 2, torch: seed + 3), its counters, and Eq. 8's targets and loss on its slice of the
features (:mod:`farsighter.agents.farsighter_loss`'s functions, which the agent alone calls too).
Its gradients, gradient clipping and optimizer steps are its own, so on CPU each seed trains bit
for bit as ``FarsighterAgent`` trains it alone (``tests/test_seeds.py``). :meth:`member` is one
seed seen as an agent, and its checkpoint is the one the run alone writes.

Seeds train as a batch where the agent alone keeps no per-row state outside what is batched here:
the posterior in ``incremental`` mode (the default; ``batch`` mode rescans each seed's replay),
no target cache (it keys on rows of one replay; the default ``general`` preset has none), fixed k
(adaptive k moves each seed's k on its own); :func:`supports` says which settings train alone.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import (
    RecentRows,
    TensorBatch,
    batch_tensors,
    build_seeded,
    crossed,
    make_optimizer,
    obs_tensor,
    row_bytes,
    td_loss,
    to_device,
    updates_owed,
    uses_gpu_replay,
)
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.farsighter import RECENT_FEATURES, FarsighterCounters, refresh_posterior
from farsighter.agents.farsighter_loss import (
    eq8_targets,
    max_targets,
    one_step_draws,
    q_taken,
    target_draws,
)
from farsighter.agents.learner import make_target_cache
from farsighter.config import Config
from farsighter.exploration import ThompsonExploration
from farsighter.networks import make_torso
from farsighter.ops.blr import BLRHead
from farsighter.replay import VectorStep
from farsighter.replay.seeds import SeedReplay
from farsighter.stacked import (
    StackedQNetwork,
    clip_per_seed,
    load_member_optimizer_state,
    member_optimizer_state,
)

ALGOS = ("farsighter", "bdqn")
"""The Bayesian algorithms with a seed-batched form."""


def supports(cfg: Config, obs_space: gym.Space | None, device: torch.device) -> str:
    """Why ``cfg`` cannot train as a seed batch here ('' when it can)."""
    if not isinstance(obs_space, gym.spaces.Box) or len(obs_space.shape or ()) == 3:
        return "image observations train their seeds one at a time (batched: flat observations)"
    if cfg.runtime.precision != "fp32" or cfg.runtime.compile or cfg.runtime.cuda_graph == "on":
        return "precision bf16, compile and cuda_graph train their seeds one at a time"
    if cfg.adaptive_k.enabled:
        return "adaptive k trains its seeds one at a time (each seed's k moves on its own)"
    if make_target_cache(cfg, device, 1) is not None:
        return (
            "the target cache trains its seeds one at a time (--runtime.target-cache off batches)"
        )
    return ""


@dataclasses.dataclass
class _SeedParts:
    """What one seed owns that the agent alone owns too."""

    head: BLRHead
    target_mean_AD: torch.Tensor
    counters: FarsighterCounters
    exploration: ThompsonExploration
    recent_phi: RecentRows
    rng: np.random.Generator
    gen: torch.Generator


class SeedBatchFarsighter:
    """S Farsighter (or BDQN) agents of one config (``cfgs`` differ only in seed) as one
    computation."""

    def __init__(
        self,
        cfgs: Sequence[Config],
        obs_space: gym.spaces.Box,
        act_space: gym.spaces.Discrete,
        *,
        device: torch.device,
    ) -> None:
        cfg = self.cfg = cfgs[0]
        self.cfgs, self.device, self.num_actions = list(cfgs), device, int(act_space.n)

        def build() -> tuple[torch.nn.Module, torch.Tensor]:  # FarsighterAgent's, draw for draw
            torso = make_torso(obs_space, cfg.hidden_sizes)
            init_AD = torch.nn.Linear(torso.out_dim, self.num_actions, bias=False).weight.detach()
            return torso, init_AD

        built = [build_seeded(c.seed, build) for c in cfgs]
        torsos = [torso for torso, _ in built]
        self.dim = int(torsos[0].out_dim)
        self.torso = StackedQNetwork(torsos).to(device)  # refuses torsos it cannot stack
        self.torso_target = StackedQNetwork(torsos).to(device)
        self.torso_target.requires_grad_(False)
        self.params = list(self.torso.parameters())
        self.opt = make_optimizer(self.params, cfg)
        self.parts: list[_SeedParts] = []
        b = cfg.blr
        for c, (_, init_AD) in zip(cfgs, built, strict=True):
            head = BLRHead(
                num_actions=self.num_actions,
                dim=self.dim,
                prior_std=b.prior_std,
                noise_std=b.noise_std,
                cov_scale=b.cov_scale,
                forgetting=b.forgetting,
                scale=b.scale,
                device=device,
            )
            head.set_mean(init_AD.to(device))
            counters = FarsighterCounters(k=cfg.k)
            gen = torch.Generator(device=device)
            gen.manual_seed(c.seed + 3)
            self.parts.append(
                _SeedParts(
                    head=head,
                    target_mean_AD=head.mean_AD.clone(),
                    counters=counters,
                    exploration=ThompsonExploration(c, head, counters),
                    recent_phi=RecentRows(RECENT_FEATURES),
                    rng=np.random.default_rng(c.seed + 2),
                    gen=gen,
                )
            )
        self.replay = SeedReplay(  # each seed's streams and generator (seed + 1), as alone
            [c.seed + 1 for c in cfgs],
            cfg.buffer_size,
            tuple(obs_space.shape or ()),
            obs_space.dtype,
            num_envs=cfg.num_envs,
            action_dtype=np.int32,
            device=device
            if uses_gpu_replay(cfg, device, row_bytes(obs_space, 1) * len(cfgs))
            else None,
        )

    @property
    def seeds(self) -> int:
        return len(self.cfgs)

    # ------------------------------------------------------------------ acting
    def act(self, obs_SE: np.ndarray, global_step: int) -> np.ndarray:
        """Each seed's actions, (S, E): uniform from its generator before ``learning_starts``,
        then Thompson sampling under its own draws (Algorithm 2)."""
        n = obs_SE.shape[1]
        if global_step < self.cfg.learning_starts:
            return np.stack([p.rng.integers(0, self.num_actions, size=n) for p in self.parts])
        with torch.no_grad():
            phi_SED = self.torso(obs_tensor(obs_SE, self.device))
            q = [
                p.exploration.q(phi_SED[s], obs_SE[s], p.gen).argmax(dim=1)
                for s, p in enumerate(self.parts)
            ]
        return torch.stack(q).cpu().numpy()

    def observe(self, steps: Sequence[VectorStep]) -> None:
        """One vector step of every seed, in seed order."""
        self.replay.add_steps(steps)
        for p, st in zip(self.parts, steps, strict=True):
            p.exploration.observe(np.logical_or(st.terminated_E, st.truncated_E))

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> list[dict[str, torch.Tensor]]:
        """The updates owed at ``global_step``, then each seed's posterior refresh and target
        copy in ``FarsighterAgent.learn``'s order; each seed's metrics as it gives them alone."""
        cfg = self.cfg
        owed = {updates_owed(p.counters, cfg, global_step) for p in self.parts}
        assert len(owed) == 1, "the seeds of a batch update together"
        metrics: list[dict[str, torch.Tensor]] = [{} for _ in self.parts]
        for _ in range(owed.pop()):
            losses = self.update()
            if losses is not None:
                metrics = [{"td_loss": loss} for loss in losses]
        copied = False
        for s, p in enumerate(self.parts):
            c = p.counters
            if global_step >= cfg.learning_starts and crossed(
                c, "refreshes", global_step, cfg.blr.posterior_every
            ):
                self._refresh(s, p)
            if crossed(c, "target_syncs", global_step, cfg.target_update_every):
                if not copied:  # every seed's torso at once
                    self.torso_target.load_state_dict(self.torso.state_dict())
                    copied = True
                p.target_mean_AD.copy_(p.head.mean_AD)
        return metrics

    def update(self) -> list[torch.Tensor] | None:
        """One step on every seed's theta with its w at its posterior mean (Eq. 8); each seed's
        loss (``FarsighterAgent.update``'s, seed by seed)."""
        cfg, S, B = self.cfg, self.seeds, self.cfg.batch_size
        k = self.parts[0].counters.k
        try:
            batch = self.replay.sample_seeds(  # sample_minibatch's, seed by seed
                B,
                k=k,
                gamma=cfg.gamma,
                recent=cfg.effective_recent_window if cfg.sample_recent else None,
                stride=k if cfg.stride else 1,
                on_device=True,
            )
        except ValueError:  # not enough complete k-step windows yet
            return None
        t = batch_tensors(batch, self.device)
        inputs: Tensors = t.tensors()
        one_step = cfg.k_target == "max" and k > 1
        if one_step:  # the larger of the k-step and the one-step target (FarsighterAgent.update)
            one = self.replay.gather(batch.env_index, batch.index, 1, cfg.gamma)
            inputs.update(
                one_next_obs_B=obs_tensor(one.next_obs, self.device),
                one_returns_B=to_device(one.returns, self.device),
                one_bootstrap_B=to_device(one.bootstrap, self.device),
            )

        def by_seed(x: torch.Tensor) -> torch.Tensor:
            return x.view(S, B, *x.shape[1:])

        with torch.no_grad():  # every seed's features of s' at once; each seed's targets
            features = {
                prefix: (
                    self.torso(by_seed(inputs[prefix + "next_obs_B"])),
                    self.torso_target(by_seed(inputs[prefix + "next_obs_B"])),
                )
                for prefix in (("", "one_") if one_step else ("",))
            }
        seeded = [{key: by_seed(x)[s] for key, x in inputs.items()} for s in range(S)]
        ys = [
            self._targets(p, mine, features, s, one_step)
            for s, (p, mine) in enumerate(zip(self.parts, seeded, strict=True))
        ]
        phi_SBD = self.torso(by_seed(t.obs_B))
        losses = [
            td_loss(q_taken(phi_SBD[s], p.head.mean_AD, mine["actions_B"]), y_B, cfg.loss)
            for s, (p, mine, y_B) in enumerate(zip(self.parts, seeded, ys, strict=True))
        ]
        self.opt.zero_grad(set_to_none=True)
        # each seed's gradient is its own loss's: d(sum)/d(loss_s) = 1 exactly
        torch.stack(losses).sum().backward()
        if cfg.max_grad_norm > 0:
            clip_per_seed(self.params, S, cfg.max_grad_norm)
        self.opt.step()
        if cfg.blr.mode == "incremental":
            self._accumulate(phi_SBD, seeded, ys, features[""][1])
        return [loss.detach() for loss in losses]

    @torch.no_grad()
    def _accumulate(
        self,
        phi_SBD: torch.Tensor,
        seeded: list[Tensors],
        ys: list[torch.Tensor],
        phi_next_target_SBD: torch.Tensor,
    ) -> None:
        """Each seed's minibatch into its posterior's statistics (``FarsighterAgent._accumulate``,
        with the regression targets its loss hands it)."""
        cfg = self.cfg
        root_w = (cfg.train_every / cfg.batch_size) ** 0.5
        for s, (p, mine, y_B) in enumerate(zip(self.parts, seeded, ys, strict=True)):
            phi_BD = phi_SBD[s].detach()
            if cfg.blr.posterior_target != "double":
                y_B = max_targets(_batch(mine), phi_next_target_SBD[s], p.target_mean_AD)
            p.head.accumulate(phi_BD * root_w, mine["actions_B"], y_B * root_w)
            p.recent_phi.add(phi_BD)

    def _targets(
        self,
        p: _SeedParts,
        mine: Tensors,
        features: dict[str, tuple[torch.Tensor, torch.Tensor]],
        s: int,
        one_step: bool,
    ) -> torch.Tensor:
        """Seed ``s``'s y of Eq. 8 on its features (``FarsighterLoss.__call__``'s targets)."""
        draws = target_draws(
            self.cfg.blr.target,
            p.head,
            len(mine["actions_B"]),
            one_step,
            p.gen,
            lambda: p.exploration.acting_draw(p.gen),
        )
        with torch.no_grad():
            kind, t = self.cfg.blr.target, _batch(mine)
            phi_next, phi_next_target = features[""]
            y_B = eq8_targets(
                p.head, p.target_mean_AD, kind, t, phi_next[s], phi_next_target[s], draws
            )
            if one_step:
                one_next, one_next_target = features["one_"]
                one = _batch(mine, "one_")
                y_B = torch.maximum(
                    y_B,
                    eq8_targets(
                        p.head,
                        p.target_mean_AD,
                        kind,
                        one,
                        one_next[s],
                        one_next_target[s],
                        one_step_draws(draws),
                    ),
                )
        return y_B

    def _refresh(self, s: int, p: _SeedParts) -> None:
        """Algorithm 1 line 6 for one seed (``FarsighterAgent.refresh_posterior``): a batch-mode
        fit runs the seed's own networks over its own streams' rows."""
        cfg = self.cfg
        double = cfg.blr.posterior_target == "double"

        def targets(t: TensorBatch) -> torch.Tensor:  # FarsighterLoss.posterior_targets
            phi_next_target = self.torso_target.member_forward(t.next_obs_B, s)
            if not double:
                return max_targets(t, phi_next_target, p.target_mean_AD)
            draws = target_draws(
                cfg.blr.target,
                p.head,
                len(t.actions_B),
                False,
                p.gen,
                lambda: p.exploration.acting_draw(p.gen),
            )
            phi_next = self.torso.member_forward(t.next_obs_B, s)
            return eq8_targets(
                p.head, p.target_mean_AD, cfg.blr.target, t, phi_next, phi_next_target, draws
            )

        refresh_posterior(
            cfg,
            p.head,
            p.counters,
            p.recent_phi,
            self.replay,
            p.rng,
            self.device,
            lambda obs: self.torso.member_forward(obs, s),
            targets,
            self.replay.seed_streams(s),
        )

    # ------------------------------------------------------------------ one seed
    def member(self, s: int) -> FarsighterSeedMember:
        return FarsighterSeedMember(self, s)


def _batch(inputs: Tensors, prefix: str = "") -> TensorBatch:
    """A seed's :class:`TensorBatch` (``prefix = "one_"``: its one-step windows, same s and a)."""
    return TensorBatch(
        obs_B=inputs["obs_B"],
        next_obs_B=inputs[prefix + "next_obs_B"],
        actions_B=inputs["actions_B"],
        returns_B=inputs[prefix + "returns_B"],
        bootstrap_B=inputs[prefix + "bootstrap_B"],
    )


class FarsighterSeedMember:
    """Seed ``s`` of a batch as an agent: what the run log, evaluation and checkpoints use."""

    def __init__(self, batch: SeedBatchFarsighter, s: int) -> None:
        self.batch, self.s = batch, s
        self.cfg = batch.cfgs[s]
        self.parts = batch.parts[s]

    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        if explore:
            raise NotImplementedError("a seed of a batch explores through the batch's act")
        with torch.no_grad():  # evaluation: greedy under the posterior mean
            return (self._phi(obs_E) @ self.parts.head.mean_AD.T).argmax(dim=1).cpu().numpy()

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        phi_BD = self._phi(obs_B)
        mean_BA = phi_BD @ self.parts.head.mean_AD.T
        return mean_BA.cpu().numpy(), self.parts.head.predictive_var(phi_BD).cpu().numpy()

    def _phi(self, obs_B: np.ndarray) -> torch.Tensor:
        """phi(s) of this seed's torso, (B, D)."""
        b = self.batch
        return b.torso.member_forward(obs_tensor(np.asarray(obs_B), b.device), self.s)

    def observe(self, step: VectorStep) -> None:
        raise NotImplementedError("a seed of a batch records its steps through the batch")

    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        raise NotImplementedError("a seed of a batch learns through the batch")

    def diagnostics(self) -> dict[str, float]:
        head, c = self.parts.head, self.parts.counters
        return {
            "k": float(c.k),
            "q_variance": c.q_variance,
            "posterior_refreshes": float(head.num_refreshes),
            "jitter_events": float(head.jitter_events),
            "noise_std": head.noise_std,
        }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """The checkpoint of ``FarsighterAgent`` alone, for this seed."""
        b, s, p = self.batch, self.s, self.parts
        return {
            "torso": b.torso.member_state(s),
            "torso_target": b.torso_target.member_state(s),
            "head": p.head.state_dict(),
            "target_mean_AD": p.target_mean_AD.clone(),
            "opt": member_optimizer_state(b.opt, s),
            "rng": p.rng.bit_generator.state,
            "gen": p.gen.get_state(),
            "counters": dataclasses.asdict(p.counters),
            "replay": b.replay.member_state(s) if include_replay else None,
            "exploration": p.exploration.state_dict(),
            "recent_phi": p.recent_phi.state_dict(),
            "target_cache": None,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """A checkpoint of this seed (written alone or in a batch). Seeds resume together only
        from checkpoints with the same counters (:func:`farsighter.seeds.train_seeds` groups
        them so)."""
        b, s, p = self.batch, self.s, self.parts
        b.torso.load_member(s, state["torso"])
        b.torso_target.load_member(s, state["torso_target"])
        p.head.load_state_dict(state["head"])
        p.target_mean_AD.copy_(state["target_mean_AD"])
        load_member_optimizer_state(b.opt, s, state["opt"])
        p.rng.bit_generator.state = state["rng"]
        p.gen.set_state(state["gen"])
        for key, value in state["counters"].items():
            setattr(p.counters, key, value)
        p.recent_phi.load_state_dict(state["recent_phi"])
        p.exploration.load_state_dict(state.get("exploration", state))
        if state.get("replay") is not None:
            b.replay.load_member(s, state["replay"])
        else:
            p.counters.hold_pending = True


SeedBatch = SeedBatchFarsighter
"""The batch class :mod:`farsighter.seeds` builds for this module's algorithms."""
