"""The replays of S seeds in one buffer: a seed axis over :class:`ReplayBuffer`'s streams.

Seed s owns streams ``s * E .. s * E + E - 1`` (E environments per seed) and its own generator,
seeded as its replay alone would be. A minibatch draws each seed's candidates from that seed's
streams with that seed's generator, exactly as :meth:`ReplayBuffer.sample` draws them alone, and
then checks and gathers every seed's rows in one pass: each seed gets the rows it would get alone,
and the batch holds them seed after seed (``S * B`` rows). :meth:`member_state` is one seed's
replay in the layout of its replay alone, so a seed's checkpoint is its run's alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from farsighter.errors import ConfigError
from farsighter.replay.buffer import Batch, ReplayBuffer, VectorStep


class SeedReplay(ReplayBuffer):
    """S replays of ``capacity`` rows over ``num_envs`` streams each, seeded by ``seeds``."""

    def __init__(
        self,
        seeds: Sequence[int],
        capacity: int,
        obs_shape: tuple[int, ...],
        obs_dtype: Any,
        *,
        num_envs: int = 1,
        **kwargs: Any,
    ) -> None:
        if capacity < num_envs:
            raise ConfigError(
                f"replay capacity ({capacity}) must be at least num_envs ({num_envs}) >= 1"
            )
        n = len(seeds)
        # capacity * n // (n * num_envs) == capacity // num_envs rows per stream, as alone
        super().__init__(capacity * n, obs_shape, obs_dtype, num_envs=n * num_envs, **kwargs)
        self.per_seed = num_envs
        self.rngs = [np.random.default_rng(seed) for seed in seeds]

    @property
    def seeds(self) -> int:
        return len(self.rngs)

    def seed_streams(self, s: int) -> slice:
        """The streams of seed ``s``."""
        return slice(s * self.per_seed, (s + 1) * self.per_seed)

    def sample_seeds(
        self,
        batch_size: int,
        *,
        k: int = 1,
        gamma: float = 0.99,
        recent: int | None = None,
        stride: int = 1,
        max_tries: int = 100,
        on_device: bool = False,
    ) -> Batch:
        """``batch_size`` valid k-step windows per seed, drawn as :meth:`ReplayBuffer.sample`
        draws them for that seed alone; the rows of seed 0, then seed 1, ..."""
        E = self.per_seed
        low_all, span_all = self.sample_span(k, recent, E)
        if not all((span_all[self.seed_streams(s)] > 0).any() for s in range(self.seeds)):
            raise ValueError("cannot sample from an empty replay buffer")
        chosen: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(self.seeds)]
        have = [0] * self.seeds
        for _ in range(max_tries):
            pending = [s for s in range(self.seeds) if have[s] < batch_size]
            if not pending:
                break
            drawn = []
            for s in pending:  # each seed's candidates from its own generator, as alone
                streams = self.seed_streams(s)
                n_cand = max(2 * (batch_size - have[s]), 8)
                e_N, l_N = self._draw_rows(
                    low_all[streams], span_all[streams], n_cand, self.rngs[s]
                )
                drawn.append((e_N + s * E, l_N))
            e_all, l_all = (
                np.concatenate([d[0] for d in drawn]),
                np.concatenate([d[1] for d in drawn]),
            )
            ok_all, _ = self.valid_mask(e_all, l_all, k, stride)  # one check for every seed
            at = 0
            for s, (e_N, l_N) in zip(pending, drawn, strict=True):
                idx = np.flatnonzero(ok_all[at : at + len(e_N)])[: batch_size - have[s]]
                at += len(e_N)
                chosen[s].append((e_N[idx], l_N[idx]))
                have[s] += idx.size
        if min(have) < batch_size:
            raise ValueError(
                "not enough valid transitions to sample from (need a complete k-step window); "
                "collect more steps before learning"
            )
        e_B = np.concatenate([e for rows in chosen for e, _ in rows])
        start_B = np.concatenate([start for rows in chosen for _, start in rows])
        return self.gather(e_B, start_B, k, gamma, on_device=on_device)

    def add_steps(
        self, steps: Sequence[VectorStep], exploratory_SE: np.ndarray | None = None
    ) -> None:
        """One vector step of every seed, in seed order, into the seeds' streams
        (``exploratory_SE``: which actions were exploratory, ``ReplayBuffer.add``'s flags)."""
        ended = any(st.final_obs_E is not None for st in steps)
        self.add(
            np.concatenate([st.obs_E for st in steps]),
            np.concatenate([st.action_E for st in steps]),
            np.concatenate([st.reward_E for st in steps]),
            np.concatenate([st.terminated_E for st in steps]),
            np.concatenate([st.truncated_E for st in steps]),
            [
                final
                for st in steps
                for final in (
                    st.final_obs_E if st.final_obs_E is not None else [None] * len(st.reward_E)
                )
            ]
            if ended
            else None,
            None if exploratory_SE is None else np.asarray(exploratory_SE).reshape(-1),
        )

    def member_state(self, s: int) -> dict[str, Any]:
        """Seed ``s``'s replay as :meth:`ReplayBuffer.state_dict` of its replay alone."""
        return {**self.streams_state(self.seed_streams(s)), "rng": self.rngs[s].bit_generator.state}

    def load_member(self, s: int, state: dict[str, Any]) -> None:
        """Inverse of :meth:`member_state` (a replay alone's ``state_dict``)."""
        streams = self.seed_streams(s)
        self.load_streams(streams, state)
        self.rngs[s].bit_generator.state = state["rng"]
        if self.mirror is not None:
            rows = np.arange(streams.start * self.capacity, streams.stop * self.capacity)
            self._to_mirror(rows.astype(np.int64))


class OneSeedReplay(ReplayBuffer):
    """One seed's replay behind :class:`SeedReplay`'s surface (an agent written over the seed
    axis, run alone): its streams, its generator and its checkpoint are the replay alone's."""

    @property
    def seeds(self) -> int:
        return 1

    def seed_streams(self, s: int) -> slice:
        return slice(0, self.num_envs)

    def sample_seeds(self, batch_size: int, **kwargs: Any) -> Batch:
        return self.sample(batch_size, **kwargs)

    def add_steps(
        self, steps: Sequence[VectorStep], exploratory_SE: np.ndarray | None = None
    ) -> None:
        self.add_step(steps[0], None if exploratory_SE is None else exploratory_SE[0])

    def member_state(self, s: int) -> dict[str, Any]:
        return self.state_dict()

    def load_member(self, s: int, state: dict[str, Any]) -> None:
        self.load_state_dict(state)
