"""Thompson exploration (Eq. 7): the weight draw each environment acts under, and when it is drawn
again.

An agent with a BLR head asks :class:`ThompsonExploration` for Q(s, a) = phi(s)^T w_a under each
environment's current draw w ~ N(mean_a, act_scale^2 cov_scale Cov_a) (``act_scale`` 1 unless
``blr.act_width`` widens it). *When* a draw is replaced is a
:class:`Schedule`, chosen by ``blr.redraw``:

* ``step`` (Algorithm 2 line 2): a fresh draw at every step for every environment, made a block
  ahead (:class:`~farsighter.ops.blr.ThompsonDraws`);
* ``every``: held for ``blr.redraw_every`` = T acting steps (BDQN's paper), ``k``: held for the
  current k (the horizon of the k-step target);
* ``episode``: held for the environment's whole episode;
* ``revisit`` (:mod:`farsighter.exploration.revisit`): held while the episode reaches new states.

``blr.revisit_action = uniform`` (``uniform-unpaid``: in an episode after one that paid nothing;
``uniform-timeout``: after one that ran to its time limit) replaces the draw's action by a
uniformly random one where the episode is back at an observation it visited
(:meth:`ThompsonExploration.actions`).

A schedule is a small class with ``due`` (the environments to redraw before this action),
``ended`` (episodes that ended) and, when it keeps state, ``state_dict``; adding one is a file
with that class and a line in ``SCHEDULES`` (docs/design.md shows one). The draws, the held
weights and the schedule's state are saved with the agent, so a resumed run draws on as the
uninterrupted one would.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from farsighter.config import Config
from farsighter.errors import ConfigError
from farsighter.exploration.revisit import EpisodeVisits
from farsighter.ops.blr import BLRHead, ThompsonDraws


class Schedule:
    """When held draws are replaced. The base holds them forever (until a shape change)."""

    def due(self, obs_E: np.ndarray, counters: Any, held: bool) -> np.ndarray | bool:
        """Environments whose draw is replaced before this action (True: all of them);
        ``held``: whether draws are held yet (False before the first)."""
        return False

    def ended(self, done_E: np.ndarray) -> np.ndarray | bool:
        """Environments to redraw at their next action, given the episodes that ended."""
        return False

    def state_dict(self) -> Any:
        return None

    def load_state_dict(self, state: Any) -> None:
        pass


class EveryT(Schedule):
    """Held for ``hold()`` acting steps, every environment at once (``every``: T, ``k``: k)."""

    def __init__(self, hold: Callable[[], int]) -> None:
        self.hold = hold

    def due(self, obs_E: np.ndarray, counters: Any, held: bool) -> np.ndarray | bool:
        due = not held or counters.steps_since_draw >= self.hold()
        if due:
            counters.steps_since_draw = 0
        counters.steps_since_draw += 1
        return due


class PerEpisode(Schedule):
    """Held for the environment's episode: redrawn at its next action after an end."""

    def ended(self, done_E: np.ndarray) -> np.ndarray | bool:
        return done_E


class Revisit(PerEpisode):
    """Held while the episode reaches new states; redrawn at its start and on a return to a
    state it has visited (:class:`~farsighter.exploration.revisit.EpisodeVisits`)."""

    def __init__(self, num_envs: int) -> None:
        self.visits = EpisodeVisits(num_envs)

    def due(self, obs_E: np.ndarray, counters: Any, held: bool) -> np.ndarray | bool:
        return self.visits.visit(obs_E)

    def ended(self, done_E: np.ndarray) -> np.ndarray | bool:
        self.visits.end(done_E)
        return done_E

    def state_dict(self) -> Any:
        return self.visits.state_dict()

    def load_state_dict(self, state: Any) -> None:
        self.visits.load_state_dict(state)


SCHEDULES: dict[str, Callable[[Config, Any], Schedule | None]] = {
    "step": lambda cfg, counters: None,  # a fresh draw per step: no held weights
    "every": lambda cfg, counters: EveryT(lambda: cfg.blr.redraw_every),
    "k": lambda cfg, counters: EveryT(lambda: counters.k),
    "episode": lambda cfg, counters: PerEpisode(),
    "revisit": lambda cfg, counters: Revisit(cfg.num_envs),
}
"""``blr.redraw`` -> its schedule (None: the draw per step of Algorithm 2)."""


class ThompsonExploration:
    """Each environment's weight draw from ``head``'s posterior and the schedule that replaces it.

    ``counters`` (the agent's) count the draws made (``draws``) and the steps a draw has been
    held (``steps_since_draw``). Draws come from the generator each call is handed (the agent's,
    which its targets share), so one seed gives one stream of numbers."""

    def __init__(self, cfg: Config, head: BLRHead, counters: Any) -> None:
        self.head, self.counters = head, counters
        self.num_envs = cfg.num_envs
        self.keep_acting_draw = cfg.blr.target == "thompson"  # the Q-loss reuses it
        if cfg.blr.redraw not in SCHEDULES:  # the config's check leaves this registry's names
            raise ConfigError(
                f"blr.redraw '{cfg.blr.redraw}' is no schedule; accepted: {', '.join(SCHEDULES)}"
            )
        self.schedule = SCHEDULES[cfg.blr.redraw](cfg, counters)
        self.draws = ThompsonDraws(head)  # the draws of a per-step schedule, a block ahead
        self.w_EAD: torch.Tensor | None = None  # the held draws (and the latest acting draw)
        self.redraw_E = np.ones(cfg.num_envs, dtype=bool)
        # blr.revisit_action: the observations each episode has visited (where it acts); with
        # a gate, whether each environment's previous episode ended well (paid, or ended before
        # its time limit), so that the draw acts at its revisits, and whether this one paid
        self.revisit_action = cfg.blr.revisit_action
        self.loops = EpisodeVisits(cfg.num_envs) if self.revisit_action != "draw" else None
        # (the first episode: uniform-unpaid breaks loops there, uniform-timeout does not, as
        # nothing ran to a time limit yet; a task without one may never end its first episode)
        gated = self.revisit_action in ("uniform-unpaid", "uniform-timeout")
        first = self.revisit_action == "uniform-timeout"
        self.well_E = np.full(cfg.num_envs, first) if gated else None
        self.paid_E = np.zeros(cfg.num_envs, dtype=bool)

    def actions(
        self, phi_ED: torch.Tensor, obs_E: np.ndarray, gen: torch.Generator
    ) -> torch.Tensor:
        """Each environment's action: the argmax of Q under its draw (:meth:`q`), and, where
        ``blr.revisit_action`` asks for it (``uniform``; ``uniform-unpaid``: in an episode
        whose environment's previous episode paid no positive reward; ``uniform-timeout``: one
        whose previous episode ran to its time limit), one uniformly at random from ``gen``
        where the environment's episode is back at an observation it visited: a draw that led
        back there would walk the same loop again."""
        actions_E = self.q(phi_ED, obs_E, gen).argmax(dim=1)
        # (an episode whose gate is shut stays so until it ends, which forgets its visits: none
        # need recording while every environment's is)
        open_E = None if self.well_E is None else ~self.well_E
        if self.loops is not None and (open_E is None or open_E.any()):
            again_E = self.loops.visit(obs_E)
            if open_E is not None:
                again_E &= open_E
            if again_E.any():
                rows = torch.as_tensor(np.flatnonzero(again_E), device=actions_E.device)
                num_actions = self.head.mean_AD.shape[0]
                uniform = torch.randint(
                    num_actions, (len(rows),), generator=gen, device=actions_E.device
                )
                actions_E[rows] = uniform
        return actions_E

    def q(self, phi_ED: torch.Tensor, obs_E: np.ndarray, gen: torch.Generator) -> torch.Tensor:
        """Q(s_e, a) = phi(s_e)^T w_ea under each environment's draw (Eq. 7), shape (E, A)."""
        n = phi_ED.shape[0]
        if self.schedule is None:  # Algorithm 2 line 2: a fresh draw for every environment
            self.counters.draws += n
            w_EAD = self.draws.take(n, gen)
            if self.keep_acting_draw:
                self.w_EAD = w_EAD.clone()  # not a view: the block is replaced, w_EAD saved
            return _q_under(phi_ED, w_EAD)
        # (no draw held yet, or held for other environments: all are drawn below)
        self.redraw_E |= self.schedule.due(obs_E, self.counters, held=self.w_EAD is not None)
        if self.w_EAD is None or self.w_EAD.shape[0] != n:
            self.w_EAD = self.head.sample_weights(n, generator=gen)
            self.counters.draws += n
            self.redraw_E[:] = False
        elif self.redraw_E.any():
            idx = np.flatnonzero(self.redraw_E)
            self.w_EAD[idx] = self.head.sample_weights(len(idx), generator=gen)
            self.counters.draws += len(idx)
            self.redraw_E[:] = False
        return _q_under(phi_ED, self.w_EAD)

    def observe(
        self,
        done_E: np.ndarray,
        reward_E: np.ndarray | None = None,
        truncated_E: np.ndarray | None = None,
    ) -> None:
        """Episodes that ended at this step (terminated or truncated), its rewards, and the
        episodes it ended at their time limit."""
        if self.schedule is not None:
            self.redraw_E |= self.schedule.ended(done_E)
        if self.loops is not None:
            self.loops.end(done_E)
        if self.well_E is None:
            return
        if self.revisit_action == "uniform-unpaid" and reward_E is not None:
            self.paid_E |= np.asarray(reward_E) > 0
            self.well_E[done_E] = self.paid_E[done_E]
            self.paid_E[done_E] = False
        elif self.revisit_action == "uniform-timeout" and truncated_E is not None:
            self.well_E[done_E] = ~np.asarray(truncated_E, dtype=bool)[done_E]

    def acting_draw(self, gen: torch.Generator) -> torch.Tensor:
        """The weights (A, D) of the latest acting draw (environment 0), for blr.target =
        thompson: the BDQN code's Q-loss takes its argmax under the one draw it acts with."""
        if self.w_EAD is None:  # no Thompson action yet (uniform warm-up): draw as the code does
            self.w_EAD = self.head.sample_weights(self.num_envs, generator=gen)
            self.counters.draws += self.num_envs
            self.redraw_E[:] = False
        return self.w_EAD[0]

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        return {  # copies: the held draws are written in place as the agent acts on
            "w_EAD": None if self.w_EAD is None else self.w_EAD.clone(),
            "draws": self.draws.state_dict(),
            "redraw_E": self.redraw_E.copy(),
            "visits": None if self.schedule is None else self.schedule.state_dict(),
            "loops": None if self.loops is None else self.loops.state_dict(),
            "ended_well": None if self.well_E is None else (self.paid_E.copy(), self.well_E.copy()),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` (what an older checkpoint holds under the agent's own keys
        loads the same way; a piece it lacks starts afresh)."""
        w = state.get("w_EAD")
        self.w_EAD = None if w is None else w.to(self.head.device, copy=True)
        self.draws.load_state_dict(state.get("draws"))
        if state.get("redraw_E") is not None:
            self.redraw_E = np.array(state["redraw_E"], dtype=bool)
        if self.schedule is not None:
            self.schedule.load_state_dict(state.get("visits"))
        if self.loops is not None:
            self.loops.load_state_dict(state.get("loops"))
        ended_well = state.get("ended_well", state.get("paid"))  # (its name before)
        if self.well_E is not None and ended_well is not None:
            paid, well = ended_well
            self.paid_E, self.well_E = np.array(paid, bool), np.array(well, bool)


def _q_under(phi_ED: torch.Tensor, w_EAD: torch.Tensor) -> torch.Tensor:
    """Q(s_e, a) = phi(s_e)^T w_ea under each environment's own weight draw, shape (E, A): one
    batched matrix-vector product (what einsum "ed,ead->ea" computes, without its parsing)."""
    return torch.bmm(w_EAD, phi_ED.unsqueeze(2)).squeeze(2)
