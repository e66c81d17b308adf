"""policy.pt holds what acting needs (issue #64 item 1): the online Q-network of DQN-family
agents; the torso, posterior mean and draw factor (float32) of the Bayesian ones; the others'
state without optimizers. load_agent acts from it alone as the agent did at the end of training."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from conftest import GrabAgent, tiny

import farsighter
from farsighter.config import make_config
from farsighter.rundir import CHECKPOINT_FILE
from farsighter.session import POLICY_FILE
from tests.conftest import inner, parts

SHORT = {
    "total_steps": 300,
    "learning_starts": 100,
    "eval_episodes": 1,
    "eval_max_steps": 50,
    "progress": False,
    "torch_threads": 1,
}


def _default_run(root: Path, algo: str) -> tuple[Path, Any]:
    """A short CartPole run with the library's defaults (network sizes, posterior), and
    the agent as training left it."""
    grab = GrabAgent()
    cfg = make_config(algo, "CartPole-v1", run_dir=str(root / algo), **SHORT)
    farsighter.train(cfg, callbacks=[grab])
    return root / algo, grab.agent


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, Any]]:
    root = tmp_path_factory.mktemp("policies")
    return {algo: _default_run(root, algo) for algo in ("ddqn", "farsighter")}


def _observations(n: int = 64) -> np.ndarray:
    return np.random.default_rng(0).normal(scale=1.5, size=(n, 4)).astype(np.float32)


def _bytes(state: dict[str, torch.Tensor]) -> int:
    return sum(t.numel() * t.element_size() for t in state.values())


def test_a_ddqn_policy_file_holds_the_online_network_alone(runs: Any) -> None:
    run, agent = runs["ddqn"]
    size = (run / POLICY_FILE).stat().st_size
    assert size < 200_000, size
    saved = torch.load(run / POLICY_FILE, weights_only=True)  # tensors and plain values only
    assert set(saved["agent"]) == {"q"}
    assert _bytes(saved["agent"]["q"]) == _bytes(inner(agent).q.member_state(0))
    checkpoint = torch.load(run / CHECKPOINT_FILE, weights_only=False)["agent"]
    assert {"q", "q_target", "opt", "rng", "counters"} <= set(checkpoint)  # resumes as before


def test_a_farsighter_policy_file_is_its_networks_and_one_factor_per_action(runs: Any) -> None:
    run, agent = runs["farsighter"]
    a, d = parts(agent).head.num_actions, parts(agent).head.dim
    assert d == 128 + 32  # the defaults: the MLP's 128 learned features and 32 random ones
    bound = _bytes(inner(agent).torso.state_dict()) + 4 * a * d * d + 4 * a * d + 32_000
    size = (run / POLICY_FILE).stat().st_size
    assert size <= bound, (size, bound)
    saved = torch.load(run / POLICY_FILE, weights_only=True)["agent"]
    assert set(saved) == {"torso", "head"}
    head = saved["head"]
    tensors = {key for key, value in head.items() if isinstance(value, torch.Tensor)}
    assert tensors == {"mean_AD", "sqrt_cov_ADD"}
    assert head["mean_AD"].dtype == head["sqrt_cov_ADD"].dtype == torch.float32
    assert torch.equal(head["sqrt_cov_ADD"], parts(agent).head.sqrt_cov_ADD.cpu())
    checkpoint = torch.load(run / CHECKPOINT_FILE, weights_only=False)["agent"]
    assert checkpoint["head"]["phiphiT_ADD"].dtype == torch.float64  # statistics stay there
    assert {"torso_target", "opt", "target_mean_AD"} <= set(checkpoint)


@pytest.mark.parametrize("algo", ["ddqn", "farsighter"])
def test_greedy_actions_from_the_policy_file_are_the_trained_agents(runs: Any, algo: str) -> None:
    run, agent = runs[algo]
    obs = _observations()
    policy = farsighter.load_agent(run)
    expected = agent.act(obs, 0, explore=False)
    np.testing.assert_array_equal(policy.act(obs), expected)
    if algo == "farsighter":  # the loaded posterior's mean and factor, as the agent acts with
        assert torch.equal(parts(policy.agent).head.mean_AD, parts(agent).head.mean_AD.cpu())
        assert torch.equal(
            parts(policy.agent).head.sqrt_cov_ADD, parts(agent).head.sqrt_cov_ADD.cpu()
        )


def test_stochastic_acting_draws_from_the_saved_factor(runs: Any) -> None:
    """act(deterministic=False) is a Thompson draw w_a = mean_a + U_a z: for two actions, action
    0 is taken with probability Phi((mu_0 - mu_1) / sqrt(v_0 + v_1)) under the saved posterior,
    not uniformly (the warm-up's uniform actions) and not greedily."""
    run, _ = runs["farsighter"]
    policy = farsighter.load_agent(run)
    head = parts(policy.agent).head
    obs = _observations(8) * 2
    with torch.no_grad():
        phi = inner(policy.agent).torso.net(torch.as_tensor(obs))
        mu = phi @ head.mean_AD.T
        var = head.predictive_var(phi) * head.act_scale**2
    z = (mu[:, 0] - mu[:, 1]) / torch.sqrt(var.sum(dim=1))
    expected = np.array([0.5 * (1 + math.erf(float(v) / math.sqrt(2))) for v in z])
    assert np.abs(expected - 0.5).max() > 0.25  # the draws tell these apart from a coin
    draws = 3_000
    actions = policy.act(np.repeat(obs, draws, axis=0), deterministic=False).reshape(-1, draws)
    np.testing.assert_allclose((actions == 0).mean(axis=1), expected, atol=0.05)


@pytest.mark.parametrize("algo", ["ob2i", "krnd"])
def test_other_agents_save_their_state_without_optimizers(tmp_path: Path, algo: str) -> None:
    grab = GrabAgent()
    farsighter.train(tiny(algo, tmp_path / "run", total_steps=600), callbacks=[grab])
    saved = torch.load(tmp_path / "run" / POLICY_FILE, weights_only=False)["agent"]
    assert not {"opt", "rnd_opt", "q_target", "replay"} & set(saved), sorted(saved)
    obs = _observations()
    policy = farsighter.load_agent(tmp_path / "run")
    np.testing.assert_array_equal(policy.act(obs), grab.agent.act(obs, 0, explore=False))


def test_a_policy_file_of_the_whole_agent_still_loads(tmp_path: Path) -> None:
    """policy.pt as earlier versions wrote it (the agent's state without its replay)."""
    grab = GrabAgent()
    farsighter.train(tiny("farsighter", tmp_path / "run", total_steps=600), callbacks=[grab])
    torch.save(grab.agent.state_dict(include_replay=False), tmp_path / "run" / POLICY_FILE)
    obs = _observations()
    policy = farsighter.load_agent(tmp_path / "run")
    np.testing.assert_array_equal(policy.act(obs), grab.agent.act(obs, 0, explore=False))
