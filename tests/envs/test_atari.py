"""Atari preprocessing on a real ALE game, and the replay rebuilding the agent's frame stacks."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ale_py", reason="Atari tests need the atari extra (installed by CI)")

from farsighter.config import make_config  # noqa: E402
from farsighter.envs import frame_stack_of, make_env, make_vector_env  # noqa: E402
from farsighter.envs.atari import ATARI_49, TABLE2, ale_id  # noqa: E402
from farsighter.replay import ReplayBuffer  # noqa: E402


def test_49_games_of_table_2() -> None:
    assert len(ATARI_49) == 49 and "MontezumaRevenge" in ATARI_49
    assert TABLE2["Breakout"].farsighter == 597.20
    assert ale_id("Pong") == "ALE/Pong-v5"


def test_preprocessing_shapes_and_life_loss() -> None:
    cfg = make_config("ddqn", "ALE/Breakout-v5")
    assert cfg.preset == "atari" and cfg.target_update_every == 10_000
    env = make_env(cfg, seed=0, training=True)
    obs, info = env.reset(seed=0)
    assert obs.shape == (4, 84, 84) and obs.dtype == np.uint8
    assert (obs[:3] == 0).all()  # zero padding before the episode start
    lives, life_terminals, rng = info.get("lives", 5), 0, np.random.default_rng(0)
    for _ in range(2_000):
        obs, reward, terminated, truncated, info = env.step(int(rng.integers(4)))
        assert reward in (-1.0, 0.0, 1.0)  # clipped for training
        if terminated or truncated:
            if "episode" in info:
                break  # the real game ended
            life_terminals += 1
            obs, info = env.reset()
    assert life_terminals >= 1  # a life loss ended a training episode without ending the game
    del lives


def test_replay_rebuilds_the_stacks_the_agent_saw() -> None:
    # Breakout with life-loss terminals: many episode starts inside 600 steps.
    cfg = make_config("ddqn", "ALE/Breakout-v5", num_envs=2)
    envs = make_vector_env(cfg, seed=1)
    buf = ReplayBuffer(2_000, (4, 84, 84), np.uint8, num_envs=2, frame_stack=frame_stack_of(cfg))
    obs, _ = envs.reset(seed=1)
    seen: list[np.ndarray] = []
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(600):
        actions = rng.integers(0, 4, size=2)
        nxt, rew, term, trunc, info = envs.step(actions)
        final = None
        if "final_obs" in info:
            final = [info["final_obs"][i] if info["_final_obs"][i] else None for i in range(2)]
            ended += int(np.sum(info["_final_obs"]))
        buf.add(obs, actions, rew, term, trunc, final)
        seen.append(obs.copy())
        obs = nxt
    assert ended >= 2  # episode boundaries (zero-padded stacks) are exercised
    for stream in (0, 1):
        rows = _logical_rows(buf, stream)
        got = buf.stacked_obs(np.full(len(rows), stream), rows)
        # Every stored start reproduces the exact stacked observation the agent acted on.
        assert np.array_equal(got, np.stack([s[stream] for s in seen]))


def _logical_rows(buf: ReplayBuffer, stream: int) -> np.ndarray:
    """Logical index of each non-final row of a stream, in order (final rows interleave)."""
    n = int(buf.count[stream])
    logical = np.arange(max(0, n - buf.capacity), n)
    flags = buf.flags[stream, logical % buf.capacity]
    return logical[(flags & 4) == 0]
