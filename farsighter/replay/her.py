"""Hindsight experience replay, "future" strategy (Andrychowicz et al. 2017), at sample time.

Design (kept small, no second buffer): with ``naf.her`` the environment factory flattens goal
observations as ``[observation, achieved_goal, desired_goal]``, so every replay row already holds
the achieved goal of its state. A sampled k-step window starting at row t is relabelled, with
probability ``ratio``, by

1. drawing a future row t' uniformly from (t, T], T the last row of t's episode (its final row,
   or the newest row while the episode is still running), and taking g' = achieved_goal(t');
2. writing g' into the desired-goal part of s_t and of the bootstrap state s_{t+n};
3. recomputing the window's rewards r_{t+j} = compute_reward(achieved_goal(t+j+1), g') for
   j < n (the task's own reward of reaching s_{t+j+1}) and their discounted sum.

The bootstrap factor is unchanged: goal tasks end by time limit, which never depends on the goal.
The stored rows are never modified; relabelling happens on the sampled copy.
"""

from __future__ import annotations

import numpy as np

from farsighter.envs.factory import GoalSpec
from farsighter.replay.buffer import FINAL, Batch, ReplayBuffer

SCAN = 64  # rows looked at per pass when searching for the end of an episode


def episode_last_rows(replay: ReplayBuffer, e_B: np.ndarray, start_B: np.ndarray) -> np.ndarray:
    """Logical index of the last row of each start's episode: its final row (the last
    observation) or, for an episode still running, the newest row written."""
    end_B = np.full(start_B.shape, -1, dtype=np.int64)
    newest_B = replay.count[e_B] - 1
    offset = 1
    while (end_B < 0).any():
        todo = np.flatnonzero(end_B < 0)
        rows_BS = start_B[todo, None] + offset + np.arange(SCAN)[None, :]
        written_BS = rows_BS <= newest_B[todo, None]
        flags_BS = replay.flags[e_B[todo, None], rows_BS % replay.capacity]
        final_BS = ((flags_BS & FINAL) != 0) & written_BS
        has_final = final_BS.any(axis=1)
        end_B[todo[has_final]] = rows_BS[has_final, final_BS[has_final].argmax(axis=1)]
        ran_out = ~has_final & ~written_BS[:, -1]
        end_B[todo[ran_out]] = newest_B[todo[ran_out]]
        offset += SCAN
    return end_B


def relabel_future(
    batch: Batch,
    replay: ReplayBuffer,
    spec: GoalSpec,
    *,
    k: int,
    gamma: float,
    ratio: float,
    rng: np.random.Generator,
) -> Batch:
    """Relabel a fraction ``ratio`` of a sampled k-step batch with future achieved goals."""
    chosen = np.flatnonzero(rng.random(len(batch.index)) < ratio)
    if chosen.size == 0:
        return batch
    e_C, t_C, n_C = batch.env_index[chosen], batch.index[chosen], batch.steps[chosen]
    end_C = episode_last_rows(replay, e_C, t_C)
    future_C = t_C + 1 + (rng.random(chosen.size) * (end_C - t_C)).astype(np.int64)
    cap = replay.capacity
    goal_CG = replay.frames[e_C, future_C % cap][:, spec.achieved]
    # Rewards of the window: reaching s_{t+j+1} under the new goal, for j < n.
    rows_CK = t_C[:, None] + 1 + np.arange(k)[None, :]
    achieved_CKG = replay.frames[e_C[:, None], rows_CK % cap][..., spec.achieved]
    goal_CKG = np.repeat(goal_CG[:, None, :], k, axis=1)
    g = spec.goal_dim
    reward_CK = np.asarray(
        spec.compute_reward(achieved_CKG.reshape(-1, g), goal_CKG.reshape(-1, g), None),
        dtype=np.float64,
    ).reshape(len(chosen), k)
    alive_CK = np.arange(k)[None, :] < n_C[:, None]
    discounts_K = gamma ** np.arange(k, dtype=np.float64)
    returns_C = (reward_CK * discounts_K * alive_CK).sum(axis=1)

    obs, next_obs, returns = batch.obs.copy(), batch.next_obs.copy(), batch.returns.copy()
    obs[chosen, spec.desired] = goal_CG
    next_obs[chosen, spec.desired] = goal_CG
    returns[chosen] = returns_C.astype(returns.dtype)
    return Batch(
        obs=obs,
        actions=batch.actions,
        returns=returns,
        bootstrap=batch.bootstrap,
        next_obs=next_obs,
        steps=batch.steps,
        env_index=batch.env_index,
        index=batch.index,
    )
