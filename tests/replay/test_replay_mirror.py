"""The replay's device mirror (Config.gpu_replay): stacks gathered from it equal the host's.

The mirror is device-generic, so these checks run it on the CPU; tests/agents/test_cuda_graph.py runs
an agent with it on a GPU when one is present."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from farsighter import make_config
from farsighter.agents.common import make_replay, row_bytes, uses_gpu_replay
from farsighter.config import validate
from farsighter.errors import ConfigError
from farsighter.replay import ReplayBuffer

G = 0.9


def random_streams(buf: ReplayBuffer, steps: int, seed: int) -> None:
    """E streams of stacked uint8 frames with random terminations and truncations: each frame
    holds a fresh random image, stacks zero-padded before every episode start."""
    rng = np.random.default_rng(seed)
    e, s = buf.num_envs, buf.frame_stack
    shape = buf.frame_shape
    stacks = np.zeros((e, s, *shape), np.uint8)
    stacks[:, -1] = rng.integers(1, 255, (e, *shape))
    for _ in range(steps):
        term = rng.random(e) < 0.08
        trunc = ~term & (rng.random(e) < 0.04)
        nxt = np.concatenate([stacks[:, 1:], rng.integers(1, 255, (e, 1, *shape))], axis=1)
        finals = [nxt[i].copy() if term[i] or trunc[i] else None for i in range(e)]
        obs = stacks if s > 1 else stacks[:, 0]
        final_obs = [f if f is None or s > 1 else f[0] for f in finals]
        buf.add(obs, rng.integers(0, 4, e), rng.normal(size=e), term, trunc, final_obs)
        for i in np.flatnonzero(term | trunc):
            nxt[i] = 0
            nxt[i, -1] = rng.integers(1, 255, shape)
        stacks = nxt


@pytest.mark.parametrize("stack", [1, 4])
def test_mirror_stacks_equal_host_stacks_after_wraparound(stack: int) -> None:
    obs_shape = (stack, 3, 3) if stack > 1 else (3, 3)
    buf = ReplayBuffer(90, obs_shape, np.uint8, num_envs=3, frame_stack=stack, device="cpu")
    random_streams(buf, 100, seed=0)  # 300 rows into 3 x 30 slots: wrapped several times
    assert buf.mirror is not None
    for e in range(3):
        rows = np.arange(max(0, buf.count[e] - buf.capacity + stack), buf.count[e])
        e_N = np.full(rows.shape, e)
        host = buf.stacked_obs(e_N, rows)
        device = buf.stacked_on_device(e_N, rows).numpy()
        assert host.shape == device.shape and np.array_equal(host, device), e
    assert not buf.mirror[-1].any()  # the padding row stays zeros


def test_sample_on_device_gives_the_host_minibatch() -> None:
    kwargs = dict(num_envs=2, frame_stack=4, seed=5)
    host = ReplayBuffer(64, (4, 5, 5), np.uint8, **kwargs)
    mirrored = ReplayBuffer(64, (4, 5, 5), np.uint8, device="cpu", **kwargs)
    random_streams(host, 70, seed=1)
    random_streams(mirrored, 70, seed=1)
    for k in (1, 3):
        a = host.sample(16, k=k, gamma=G, recent=40)
        b = mirrored.sample(16, k=k, gamma=G, recent=40, on_device=True)
        assert isinstance(b.obs, torch.Tensor) and isinstance(b.next_obs, torch.Tensor)
        assert np.array_equal(a.index, b.index) and np.array_equal(a.env_index, b.env_index)
        assert np.array_equal(a.obs, b.obs.numpy())
        assert np.array_equal(a.next_obs, b.next_obs.numpy())
        assert np.array_equal(a.returns, b.returns) and np.array_equal(a.actions, b.actions)
    # without on_device the mirrored replay still answers with host arrays
    assert isinstance(mirrored.sample(4, k=1, gamma=G).obs, np.ndarray)


def test_loaded_replay_fills_its_mirror() -> None:
    src = ReplayBuffer(40, (2, 3, 3), np.uint8, num_envs=2, frame_stack=2, seed=3)
    random_streams(src, 30, seed=2)
    dst = ReplayBuffer(40, (2, 3, 3), np.uint8, num_envs=2, frame_stack=2, device="cpu")
    dst.load_state_dict(src.state_dict())
    assert dst.mirror is not None
    assert np.array_equal(dst.mirror[:-1].numpy(), src.frames.reshape(-1, 3, 3))
    x = src.sample(8, k=2, gamma=G)
    y = dst.sample(8, k=2, gamma=G, on_device=True)
    assert np.array_equal(x.obs, y.obs.numpy()) and np.array_equal(x.next_obs, y.next_obs.numpy())


def test_stacking_without_a_mirror_on_device_is_refused() -> None:
    buf = ReplayBuffer(10, (2, 2), np.uint8)
    with pytest.raises(ValueError, match="no device mirror"):
        buf.stacked_on_device(np.array([0]), np.array([0]))


def test_agents_mirror_only_on_cuda_with_gpu_replay_auto() -> None:
    cfg = make_config("ddqn", "CartPole-v1")
    assert not uses_gpu_replay(cfg, torch.device("cpu"))
    assert uses_gpu_replay(cfg, torch.device("cuda"), 16, free_bytes=2**30)
    off = make_config("ddqn", "CartPole-v1", gpu_replay="off")
    assert not uses_gpu_replay(off, torch.device("cuda"), 16, free_bytes=2**30)
    space = gym.spaces.Box(0, 1, (4,), np.float32)
    assert make_replay(cfg, space, 1, seed=0, device=torch.device("cpu")).mirror is None


def test_gpu_replay_auto_leaves_out_a_mirror_that_does_not_fit() -> None:
    cfg = make_config("ddqn", "ALE/Breakout-v5", buffer_size=1_000_000)
    frames = gym.spaces.Box(0, 255, (4, 84, 84), np.uint8)
    row = row_bytes(frames, 4)
    assert row == 84 * 84
    cuda = torch.device("cuda")
    assert uses_gpu_replay(cfg, cuda, row, free_bytes=20 * 2**30)  # 6.6 GiB of 20 free
    with pytest.warns(UserWarning, match="gathered on the host"):
        assert not uses_gpu_replay(cfg, cuda, row, free_bytes=10 * 2**30)


def test_bad_gpu_replay_value_is_refused() -> None:
    with pytest.raises(ConfigError, match="gpu_replay must be auto or off"):
        validate(make_config("ddqn", "CartPole-v1", gpu_replay="on"))
