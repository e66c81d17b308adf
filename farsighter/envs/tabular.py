"""Small finite MDPs given by their tables, for the exploration suite's score families.

Each task is a :class:`TabularEnv`: a transition table ``P[s, a, s']``, a mean reward table
``R[s, a, s']``, a reward noise table ``sd[s, a]`` (Gaussian, 0 for a deterministic reward),
terminal states and a start state, under a time limit. The observation is the state's index
(``Discrete``; the factory turns it into a one-hot vector), so the same tables give the exact
reference returns a normalised score needs: :func:`reference_returns` solves the time-limited
MDP by backward induction for the best return and evaluates the uniform random policy the same
way, both undiscounted over the time limit, as an episode's return is counted.

Registered ids (importing this module registers them):

* ``farsighter/RiverSwim-v0``: Strehl & Littman (2008), in the form of Osband et al. (2013,
  "(More) efficient reinforcement learning via posterior sampling", section 6): six states in a
  row, start at the left end; swimming left always succeeds and pays 5/1000 at the left end;
  swimming right succeeds with probability 0.35 (0.6 from the left end), stays with 0.6 and
  drifts back with 0.05; at the right end it stays there with probability 0.6 and pays 1.
  Episodes of 20 steps. A small, sure reward beside the start; a large one at the far end.
* ``farsighter/SixArms-v0``: Strehl & Littman (2008): a hub and six rooms. From the hub, arm i
  enters room i with probability 1, 0.15, 0.1, 0.05, 0.03, 0.01 (else the hub again, paying 0);
  in room i its own arm stays and pays 50, 133, 300, 800, 1,660, 6,000, any other action goes
  back to the hub. Episodes of 25 steps. Rewards in the thousands; the best rooms rarely entered.
* ``farsighter/DistractorCorridor-v0``: a corridor of 12 cells, start in the second; stepping
  left off the start ends the episode with 0.1, reaching the right end ends it with 1; a third
  action stays put. Episodes of 36 steps. The small reward is one step away, the large one ten.
* ``farsighter/DistractorGrid-v0``: a 6 x 6 grid, start in a corner; the neighbouring cell to
  its right ends the episode with 0.2, the opposite corner with 1; a move slips to a random
  neighbour with probability 0.1. Episodes of 30 steps.
* ``farsighter/CashOutLadder-v0``: a ladder of 6 rungs; on rung i, "cash out" ends the episode
  with a reward of mean 10 * 4^i and standard deviation half of it (10 to 10,240), "climb"
  succeeds with probability 0.7 (else stays), "wait" stays. Episodes of 18 steps. Stochastic
  rewards from tens to ten thousands, the larger further up.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium
import numpy as np
from numpy.typing import NDArray

__all__ = ["TABULAR_TASKS", "TabularEnv", "TabularMDP", "reference_returns"]


@dataclass(frozen=True)
class TabularMDP:
    """A finite MDP's tables (see the module docstring)."""

    P: NDArray[np.float64]  # (S, A, S): transition probabilities
    R: NDArray[np.float64]  # (S, A, S): mean reward of the transition
    sd: NDArray[np.float64]  # (S, A): standard deviation of the reward's Gaussian noise
    terminal: NDArray[np.bool_]  # (S,): entering this state ends the episode
    start: int
    time_limit: int
    source: str

    def __post_init__(self) -> None:
        S, A, S2 = self.P.shape
        if S != S2 or self.R.shape != self.P.shape or self.sd.shape != (S, A):
            raise ValueError("P and R must be (S, A, S) and sd (S, A)")
        if not np.allclose(self.P.sum(axis=2), 1.0):
            raise ValueError("every row of P must sum to 1")


def riverswim(n: int = 6) -> TabularMDP:
    P = np.zeros((n, 2, n))
    R = np.zeros((n, 2, n))
    left, right = 0, 1
    for s in range(n):
        P[s, left, max(s - 1, 0)] = 1.0
        if s == 0:
            P[s, right, 0], P[s, right, 1] = 0.4, 0.6
        elif s == n - 1:
            P[s, right, s], P[s, right, s - 1] = 0.6, 0.4
        else:
            P[s, right, s - 1], P[s, right, s], P[s, right, s + 1] = 0.05, 0.6, 0.35
    R[0, left, 0] = 5 / 1000
    R[n - 1, right, n - 1] = 1.0
    return TabularMDP(
        P, R, np.zeros((n, 2)), np.zeros(n, bool), 0, 20,
        "Strehl & Littman 2008; Osband et al. 2013, section 6",
    )  # fmt: skip


SIX_ARMS_P = (1.0, 0.15, 0.1, 0.05, 0.03, 0.01)
SIX_ARMS_R = (50.0, 133.0, 300.0, 800.0, 1660.0, 6000.0)


def six_arms() -> TabularMDP:
    n, A = 7, 6
    P = np.zeros((n, A, n))
    R = np.zeros((n, A, n))
    for a, p in enumerate(SIX_ARMS_P):
        P[0, a, a + 1], P[0, a, 0] = p, 1.0 - p
    for room in range(1, n):
        for a in range(A):
            if a == room - 1:
                P[room, a, room] = 1.0
                R[room, a, room] = SIX_ARMS_R[room - 1]
            else:
                P[room, a, 0] = 1.0
    return TabularMDP(
        P, R, np.zeros((n, A)), np.zeros(n, bool), 0, 25, "Strehl & Littman 2008, Figure 1"
    )


def distractor_corridor(length: int = 12) -> TabularMDP:
    n, A = length, 3  # 0: left, 1: right, 2: stay
    P = np.zeros((n, A, n))
    R = np.zeros((n, A, n))
    terminal = np.zeros(n, bool)
    terminal[0] = terminal[n - 1] = True
    for s in range(n):
        if terminal[s]:
            P[s, :, s] = 1.0  # never reached: the episode ends on entry
            continue
        P[s, 0, s - 1] = P[s, 1, s + 1] = P[s, 2, s] = 1.0
    R[1, 0, 0] = 0.1
    R[n - 2, 1, n - 1] = 1.0
    return TabularMDP(P, R, np.zeros((n, A)), terminal, 1, 3 * length, "this module (ours)")


def distractor_grid(side: int = 6, slip: float = 0.1) -> TabularMDP:
    n, A = side * side, 4  # up, right, down, left
    moves = ((-1, 0), (0, 1), (1, 0), (0, -1))

    def step(s: int, a: int) -> int:
        r, c = divmod(s, side)
        r2, c2 = r + moves[a][0], c + moves[a][1]
        return r2 * side + c2 if 0 <= r2 < side and 0 <= c2 < side else s

    small, large = 1, n - 1
    terminal = np.zeros(n, bool)
    terminal[[small, large]] = True
    P = np.zeros((n, A, n))
    R = np.zeros((n, A, n))
    for s in range(n):
        for a in range(A):
            if terminal[s]:
                P[s, a, s] = 1.0
                continue
            P[s, a, step(s, a)] += 1.0 - slip
            for b in range(A):
                P[s, a, step(s, b)] += slip / A
            R[s, a, small], R[s, a, large] = 0.2, 1.0
    return TabularMDP(P, R, np.zeros((n, A)), terminal, 0, 5 * side, "this module (ours)")


def cash_out_ladder(rungs: int = 6, p_climb: float = 0.7) -> TabularMDP:
    n, A = rungs + 1, 3  # states 0..rungs-1 are rungs, state rungs the cashed-out end
    end = rungs
    P = np.zeros((n, A, n))
    R = np.zeros((n, A, n))
    sd = np.zeros((n, A))
    terminal = np.zeros(n, bool)
    terminal[end] = True
    P[end, :, end] = 1.0
    for s in range(rungs):
        mean = 10.0 * 4.0**s
        P[s, 0, end], R[s, 0, end], sd[s, 0] = 1.0, mean, mean / 2  # cash out
        top = min(s + 1, rungs - 1)
        P[s, 1, top] += p_climb
        P[s, 1, s] += 1.0 - p_climb
        P[s, 2, s] = 1.0
    return TabularMDP(P, R, sd, terminal, 0, 3 * rungs, "this module (ours)")


TABULAR_TASKS = {
    "farsighter/RiverSwim-v0": riverswim,
    "farsighter/SixArms-v0": six_arms,
    "farsighter/DistractorCorridor-v0": distractor_corridor,
    "farsighter/DistractorGrid-v0": distractor_grid,
    "farsighter/CashOutLadder-v0": cash_out_ladder,
}
"""Registered id -> the function that builds its tables."""


class TabularEnv(gymnasium.Env[np.int64, np.int64]):
    """A :class:`TabularMDP` as a Gymnasium environment; the time limit is the registry's."""

    metadata = {"render_modes": []}

    def __init__(self, task: str = "farsighter/RiverSwim-v0") -> None:
        if task not in TABULAR_TASKS:
            raise ValueError(f"unknown tabular task {task!r}; accepted: {', '.join(TABULAR_TASKS)}")
        self.mdp = TABULAR_TASKS[task]()
        S, A, _ = self.mdp.P.shape
        self.observation_space = gymnasium.spaces.Discrete(S)
        self.action_space = gymnasium.spaces.Discrete(A)
        self._s = self.mdp.start

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.int64, dict[str, Any]]:
        super().reset(seed=seed)
        self._s = self.mdp.start
        return np.int64(self._s), {}

    def step(self, action: Any) -> tuple[np.int64, float, bool, bool, dict[str, Any]]:
        a = int(action)
        s2 = int(self.np_random.choice(self.mdp.P.shape[2], p=self.mdp.P[self._s, a]))
        reward = float(self.mdp.R[self._s, a, s2])
        if self.mdp.sd[self._s, a] > 0:
            reward += float(self.mdp.sd[self._s, a] * self.np_random.standard_normal())
        self._s = s2
        return np.int64(s2), reward, bool(self.mdp.terminal[s2]), False, {}


def reference_returns(mdp: TabularMDP) -> tuple[float, float]:
    """(uniform random policy's, best) expected undiscounted return of an episode from the start
    state under the time limit, by backward induction over the remaining steps. The best is the
    finite-horizon optimum (a policy that may depend on the steps left): an upper bound on what
    a stationary agent can return, exact where the best policy is stationary."""
    S, A, _ = mdp.P.shape
    cont = (~mdp.terminal).astype(np.float64)
    v_opt = np.zeros(S)
    v_rand = np.zeros(S)
    step_reward = (mdp.P * mdp.R).sum(axis=2)  # (S, A)
    for _ in range(mdp.time_limit):
        q_opt = step_reward + mdp.P @ (cont * v_opt)
        q_rand = step_reward + mdp.P @ (cont * v_rand)
        v_opt, v_rand = q_opt.max(axis=1), q_rand.mean(axis=1)
    return float(v_rand[mdp.start]), float(v_opt[mdp.start])


for _id in TABULAR_TASKS:
    if _id not in gymnasium.registry:
        gymnasium.register(
            id=_id,
            entry_point="farsighter.envs.tabular:TabularEnv",
            max_episode_steps=TABULAR_TASKS[_id]().time_limit,
            kwargs={"task": _id},
        )
