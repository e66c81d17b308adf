"""The target cache: stored rows come back, collisions and clears are misses, and an agent with
it trains as one without it (same targets up to float rounding, across target copies)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from farsighter.replay.target_cache import TargetCache
from tests.agents.test_farsighter_agent import feed, make_agent
from tests.conftest import inner, parts


def _net_rows(e_B: np.ndarray, l_B: np.ndarray) -> torch.Tensor:
    """A stand-in network: each row's output is a function of its key."""
    key = torch.from_numpy(e_B * 1000 + l_B).float()
    return torch.stack([key, -key, key * 0.5], dim=1)


def test_lookup_computes_misses_once_and_returns_stored_rows() -> None:
    cache = TargetCache(num_envs=2, rows_per_env=8, width=3, device=torch.device("cpu"))
    calls: list[int] = []

    def lookup(e_B: np.ndarray, l_B: np.ndarray) -> torch.Tensor:
        def compute(i: np.ndarray) -> torch.Tensor:
            calls.append(len(i))
            return _net_rows(e_B[i], l_B[i])

        return cache.lookup(e_B, l_B, compute)

    e, rows = np.array([0, 1, 0, 1]), np.array([3, 3, 5, 6])
    assert torch.equal(lookup(e, rows), _net_rows(e, rows)) and calls == [4]
    e2, rows2 = np.array([1, 0, 0]), np.array([6, 3, 7])
    assert torch.equal(lookup(e2, rows2), _net_rows(e2, rows2)) and calls == [4, 1]  # one new
    assert (cache.hits, cache.misses) == (2, 5)
    # rows 3 and 11 share a slot (11 % 8 == 3), in one batch and across batches: never mixed up
    e3, rows3 = np.array([0, 0, 0]), np.array([11, 3, 11])
    assert torch.equal(lookup(e3, rows3), _net_rows(e3, rows3))
    assert torch.equal(lookup(e3[:1], rows3[:1]), _net_rows(e3[:1], rows3[:1]))
    assert torch.equal(lookup(e3[1:2], rows3[1:2]), _net_rows(e3[1:2], rows3[1:2]))
    cache.clear()
    before = len(calls)
    assert torch.equal(lookup(e, rows), _net_rows(e, rows)) and calls[before:] == [4]


def test_state_round_trip_keeps_the_stored_rows() -> None:
    cache = TargetCache(num_envs=1, rows_per_env=16, width=3, device=torch.device("cpu"))
    e, rows = np.zeros(5, dtype=np.int64), np.array([1, 2, 3, 9, 15])
    cache.lookup(e, rows, lambda i: _net_rows(e[i], rows[i]))
    other = TargetCache(num_envs=1, rows_per_env=16, width=3, device=torch.device("cpu"))
    other.load_state_dict(cache.state_dict())

    def never(i: np.ndarray) -> torch.Tensor:
        raise AssertionError("a stored row was computed again")

    assert torch.equal(other.lookup(e, rows, never), _net_rows(e, rows))
    with pytest.raises(ValueError, match="must be >= 1"):
        TargetCache(num_envs=1, rows_per_env=0, width=3, device=torch.device("cpu"))


def test_an_agent_with_the_cache_trains_as_one_without(tmp_path: Path) -> None:
    kw = dict(sample_recent=True, target_update_every=40, k=3, k_target="max", batch_size=16)
    agents = {
        mode: make_agent(tmp_path / mode, target_cache=mode, **kw)  # type: ignore[arg-type]
        for mode in ("auto", "off")
    }
    assert parts(agents["auto"]).cache is not None and parts(agents["off"]).cache is None
    losses: dict[str, list[float]] = {"auto": [], "off": []}
    for mode, agent in agents.items():
        feed(agent, 100, seed=4)
        for step in range(100, 400):  # 300 updates, 7 target copies
            feed(agent, 1, seed=step)
            loss = inner(agent).update()
            assert loss is not None
            losses[mode].append(float(loss))
            agent.learn(step)  # target copies (and posterior refreshes) where they fall
    cache = parts(agents["auto"]).cache
    assert cache is not None and cache.hits > cache.misses > 0  # rows were reused
    np.testing.assert_allclose(losses["auto"], losses["off"], rtol=1e-4, atol=1e-6)
    for a, b in zip(
        inner(agents["auto"]).torso.parameters(),
        inner(agents["off"]).torso.parameters(),
        strict=True,
    ):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5)


def test_a_state_saved_with_another_setting_or_before_the_cache_loads(tmp_path: Path) -> None:
    cached = make_agent(tmp_path / "a", sample_recent=True, target_cache="auto")
    plain = make_agent(tmp_path / "b", sample_recent=True, target_cache="off")
    for agent in (cached, plain):
        feed(agent, 200, seed=1)
        for _ in range(5):
            inner(agent).update()
    assert parts(cached).cache is not None and parts(cached).cache.misses > 0
    plain.load_state_dict(cached.state_dict())  # the cache's state is left aside
    assert parts(plain).cache is None and inner(plain).update() is not None
    cached.load_state_dict(plain.state_dict())  # none saved: the cache starts empty
    assert parts(cached).cache is not None and not (parts(cached).cache.tags >= 0).any()
    old = cached.state_dict()
    old.update(old.pop("exploration"))  # the layout before the exploration object
    del old["draws"], old["target_cache"]  # a checkpoint from before both
    cached.load_state_dict(old)
    assert inner(cached).update() is not None
    feed(cached, 1, seed=2)
    assert cached.act(np.zeros((1, 4), np.float32), 10).shape == (1,)


def test_the_target_cache_empties_when_the_target_torsos_are_copied_or_loaded(
    tmp_path: Path,
) -> None:
    """Rows cached under the old target torso are never read after the hard copy (Algorithm 1
    line 8) or any other load of the target torsos."""
    agent = make_agent(tmp_path, sample_recent=True, target_cache="auto")
    feed(agent, 200, seed=1)
    loss, cache = inner(agent).loss, parts(agent).cache
    assert cache is not None
    for empty in (
        loss.copy_target,
        lambda: loss.torso_target.load_state_dict(loss.torso.state_dict()),
    ):
        assert inner(agent).update() is not None
        assert (cache.tags >= 0).any()
        empty()
        assert not (cache.tags >= 0).any()
