"""The update step as a CUDA graph (farsighter.agents.cuda_graph).

On any machine: what a captured step relies on (the tensors it reads between updates are updated
in place, never rebound), the config rules and the optimizer's capturable flag. With a CUDA
device (the GPU benchmark machine; ``pytest tests/agents/test_cuda_graph.py``): a graphed agent makes
the same updates as an eager one, through target copies, posterior refreshes and a checkpoint
load.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

from farsighter import make_config
from farsighter.agents import build_agent
from farsighter.agents.cuda_graph import graphs_enabled, set_capturable
from farsighter.config import validate
from farsighter.errors import ConfigError
from farsighter.ops.blr import BLRHead
from tests.agents.test_farsighter_agent import feed as _feed
from tests.conftest import inner, parts, tiny

CUDA = torch.cuda.is_available()


def _agent(tmp_path: Path, algo: str, device: str = "cpu", **kw: Any) -> Any:
    # eager agents without the target cache, so that eager and graphed updates compare alike
    # (the cache against none: tests/replay/test_target_cache.py)
    kw.setdefault("target_cache", "off")
    cfg = tiny(algo, tmp_path, learning_starts=0, device=device, **kw)
    env = gym.make("CartPole-v1")
    return build_agent(
        cfg, env.observation_space, env.action_space, frame_stack=1, device=torch.device(device)
    )


# ---------------------------------------------------------------------------------- any machine


def test_blr_head_refreshes_its_float32_posterior_in_place() -> None:
    torch.manual_seed(0)
    head = BLRHead(num_actions=3, dim=5, prior_std=1.0, noise_std=1.0, device=torch.device("cpu"))
    cached = (head.mean_AD, head.sqrt_cov_ADD, head._sqrt_cov32_DX)  # what q_noise reads too
    ptrs = [t.data_ptr() for t in cached]
    mean, before = head.mean_AD, head.mean_AD.clone()
    head.fit(torch.randn(50, 5), torch.randint(0, 3, (50,)), torch.randn(50))
    assert [t.data_ptr() for t in (head.mean_AD, head.sqrt_cov_ADD, head._sqrt_cov32_DX)] == ptrs
    assert head.mean_AD is mean and not torch.equal(mean, before)  # new values, same tensor
    head.set_mean(torch.ones(3, 5))
    assert head.mean_AD.data_ptr() == ptrs[0] and torch.equal(mean, torch.ones(3, 5))

    # q_noise with given normals is phi^T U_a z_a
    phi, z = torch.randn(4, 5), torch.randn(4, 3, 5)
    expected = (
        torch.stack([((phi @ head.sqrt_cov_ADD[a]) * z[:, a]).sum(-1) for a in range(3)], dim=1)
        * head.cov_scale**0.5
    )
    torch.testing.assert_close(head.q_noise(phi, z_BAD=z), expected)
    other = BLRHead(num_actions=3, dim=5, prior_std=1.0, noise_std=1.0, device=torch.device("cpu"))
    other.load_state_dict(head.state_dict())
    torch.testing.assert_close(other.mean_AD, head.mean_AD, rtol=0, atol=0)


@pytest.mark.parametrize("algo", ["ddqn", "bdqn", "farsighter"])
def test_what_the_captured_step_reads_is_updated_in_place(tmp_path: Path, algo: str) -> None:
    agent = _agent(tmp_path, algo, target_update_every=10, blr__posterior_every=10)
    online, target = (
        (inner(agent).q, inner(agent).loss.q_target)
        if algo == "ddqn"
        else (inner(agent).torso, inner(agent).loss.torso_target)
    )
    tensors = list(online.parameters()) + list(target.parameters())
    if algo != "ddqn":
        tensors += [parts(agent).head.mean_AD, parts(agent).target_mean_AD]
    ptrs = [t.data_ptr() for t in tensors]
    target_before = [p.clone() for p in target.parameters()]
    _feed(agent, 200)
    for step in range(1, 61):  # updates, target copies and (farsighter family) refreshes
        agent.learn(step)
    counters = inner(agent).counters if algo == "ddqn" else parts(agent).counters
    assert counters.target_syncs >= 5
    assert [t.data_ptr() for t in tensors] == ptrs
    assert not all(
        torch.equal(a, b) for a, b in zip(target.parameters(), target_before, strict=True)
    )
    if algo != "ddqn":
        assert counters.refreshes >= 5
        torch.testing.assert_close(
            parts(agent).target_mean_AD, parts(agent).head.mean_AD
        )  # copied at line 8


def test_cuda_graph_setting_is_checked() -> None:
    with pytest.raises(ConfigError, match="cuda_graph on needs a CUDA device"):
        validate(make_config("ddqn", "CartPole-v1", device="cpu", cuda_graph="on"))
    with pytest.raises(ConfigError, match="cuda_graph on is supported by"):
        validate(make_config("ob2i", "CartPole-v1", cuda_graph="on"))
    with pytest.raises(ConfigError, match="cuda_graph must be"):
        validate(make_config("ddqn", "CartPole-v1", cuda_graph="yes"))
    # device auto: allowed, for a run that keeps its update's branch (optimism until the
    # first reward switches it: refused, not silently left eager)
    validate(make_config("farsighter", "CartPole-v1", cuda_graph="on", blr__optimism="always"))
    validate(make_config("farsighter", "CartPole-v1", cuda_graph="on"))  # the defaults
    with pytest.raises(ConfigError, match="does not combine with blr.optimism until-reward"):
        validate(
            make_config("farsighter", "CartPole-v1", cuda_graph="on", blr__optimism="until-reward")
        )
    with pytest.raises(ConfigError, match="needs a CUDA device"):  # ... until it resolves to CPU
        graphs_enabled("on", torch.device("cpu"), supported=True)
    assert graphs_enabled("auto", torch.device("cpu"), supported=True) is False
    assert graphs_enabled("auto", torch.device("cuda"), supported=True) is True
    assert graphs_enabled("auto", torch.device("cuda"), supported=False) is False
    assert graphs_enabled("off", torch.device("cuda"), supported=True) is False


def test_eager_on_cpu_with_the_default_setting(tmp_path: Path) -> None:
    agent = _agent(tmp_path, "farsighter")
    assert inner(agent).learner.graphs is False and not hasattr(inner(agent).learner.step, "replay")
    assert all(g["capturable"] is False for g in inner(agent).learner.opt.param_groups)


def test_set_capturable_follows_a_loaded_state(tmp_path: Path) -> None:
    agent = _agent(tmp_path, "ddqn")
    _feed(agent, 100)
    agent.learn(20)
    state = inner(agent).learner.opt.state_dict()
    for g in state["param_groups"]:
        g["capturable"] = True  # as a GPU run with graphs saves it
    inner(agent).learner.opt.load_state_dict(state)
    set_capturable(inner(agent).learner.opt, False)
    assert all(g["capturable"] is False for g in inner(agent).learner.opt.param_groups)
    steps = [s["step"] for s in inner(agent).learner.opt.state.values()]
    assert steps and all(s.device.type == "cpu" and s.dtype == torch.float32 for s in steps)
    agent.learn(40)  # the optimizer steps again on the CPU


# ------------------------------------------------------------------------------ CUDA machines


def _params(agent: Any) -> list[torch.Tensor]:
    net = inner(agent).q if hasattr(inner(agent), "q") else inner(agent).torso
    return [p.detach().cpu().clone() for p in net.parameters()]


@pytest.mark.skipif(not CUDA, reason="needs a CUDA device (run on the GPU benchmark machine)")
@pytest.mark.parametrize(
    ("algo", "extra"),
    [
        ("ddqn", {}),
        ("rnd", {}),
        ("bdqn", {}),
        ("farsighter", {"k_target": "max"}),  # tiny's control preset: blr.target thompson
        ("farsighter", {"k_target": "max", "blr__target": "sample"}),
        ("farsighter", {"blr__target": "mean"}),
        ("farsighter", {"blr__mode": "incremental"}),
        ("farsighter", {"precision": "bf16"}),
    ],
)
def test_graphed_updates_equal_eager_updates(
    tmp_path: Path, algo: str, extra: dict[str, Any]
) -> None:
    kw = {"target_update_every": 25, "blr__posterior_every": 40, **extra}
    runs = []
    for setting in ("off", "on"):
        agent = _agent(tmp_path / setting, algo, device="cuda", cuda_graph=setting, **kw)
        _feed(agent, 300)
        losses = []
        for step in range(1, 241):  # 120 updates: warm-up, capture, replays, copies, refreshes
            m = agent.learn(step)
            if "td_loss" in m:
                losses.append(float(m["td_loss"]))
        runs.append((agent, losses))
    (eager, eager_losses), (graphed, graphed_losses) = runs
    step = inner(graphed).learner.step
    assert step.captures >= 1 and step.replays >= 100
    np.testing.assert_allclose(graphed_losses, eager_losses, rtol=1e-4, atol=1e-6)
    for a, b in zip(_params(graphed), _params(eager), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5)
    if algo in ("bdqn", "farsighter"):  # the agents with a BLR head
        torch.testing.assert_close(
            parts(graphed).head.mean_AD, parts(eager).head.mean_AD, rtol=1e-4, atol=1e-5
        )


@pytest.mark.skipif(not CUDA, reason="needs a CUDA device (run on the GPU benchmark machine)")
@pytest.mark.parametrize("algo", ["ddqn", "farsighter"])
def test_minibatches_from_the_gpu_replay_mirror_make_the_same_updates(
    tmp_path: Path, algo: str
) -> None:
    runs = []
    for setting in ("off", "auto"):
        agent = _agent(tmp_path / setting, algo, device="cuda", gpu_replay=setting)
        assert (inner(agent).replay.mirror is not None) == (setting == "auto")
        _feed(agent, 300)
        losses = [float(agent.learn(step).get("td_loss", np.nan)) for step in range(1, 121)]
        runs.append((agent, losses))
    (host, host_losses), (mirrored, mirrored_losses) = runs
    np.testing.assert_allclose(mirrored_losses, host_losses, rtol=1e-4, atol=1e-6)
    for a, b in zip(_params(mirrored), _params(host), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize(
    "device",
    ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not CUDA, reason="needs CUDA"))],
)
def test_an_agent_loaded_from_another_continues_as_it_would(tmp_path: Path, device: str) -> None:
    """Loading another agent's state copies it (no shared optimizer or posterior tensors) and,
    with graphs, captures afresh: both then make the same updates."""
    graphs = "on" if device == "cuda" else "off"
    a = _agent(tmp_path / "a", "farsighter", device=device, cuda_graph=graphs)
    b = _agent(tmp_path / "b", "farsighter", device=device, cuda_graph="off")
    for agent in (a, b):
        _feed(agent, 300)
        for step in range(1, 31):
            agent.learn(step)
    a.load_state_dict(b.state_dict())  # rebinds target_mean_AD and the head's statistics
    for agent in (a, b):
        for step in range(31, 61):
            agent.learn(step)
    if device == "cuda":
        assert inner(a).learner.step.captures == 2
    for x, y in zip(_params(a), _params(b), strict=True):
        torch.testing.assert_close(x, y, rtol=1e-4, atol=1e-5)


@pytest.mark.skipif(CUDA, reason="checks the refusal on a machine without CUDA")
def test_cuda_graph_on_without_a_gpu_is_refused_before_the_run_dir(tmp_path: Path) -> None:
    from farsighter import train

    cfg = tiny("ddqn", tmp_path / "run", cuda_graph="on")  # device auto resolves to the CPU
    with pytest.raises(ConfigError, match="needs a CUDA device"):
        train(cfg)
    assert not (tmp_path / "run").exists()


def _cuda_generator_state(seed: int, offset: int) -> torch.Tensor:
    """A CUDA generator's saved state (its seed and offset, 16 bytes), made without a GPU."""
    return torch.tensor(np.array([seed, offset], dtype=np.int64).view(np.uint8))


def test_a_checkpoint_saved_on_another_device_loads(tmp_path: Path) -> None:
    """A GPU run's agent loads on a CPU (``load_agent``, a resume): its generator's state has
    another form, so the generator is seeded from the saved bytes: the same draws for the same
    checkpoint, other draws for another."""
    gpu_state = _agent(tmp_path / "saved", "farsighter").state_dict()
    draws = []
    for seed in (7, 7, 8):
        gpu_state["gen"] = _cuda_generator_state(seed, 4)
        if CUDA:  # the real thing where there is one
            gen = torch.Generator(device="cuda")
            gen.manual_seed(seed)
            gpu_state["gen"] = gen.get_state()
        agent = _agent(tmp_path / f"loaded{len(draws)}", "farsighter")
        agent.load_state_dict(gpu_state)
        draws.append(torch.rand(5, generator=parts(agent).gen))
    assert torch.equal(draws[0], draws[1]) and not torch.equal(draws[0], draws[2])


@pytest.mark.skipif(not CUDA, reason="needs a CUDA device (run on the GPU benchmark machine)")
def test_a_graphed_update_takes_advantage_learning_after_the_switch(tmp_path: Path) -> None:
    """Mean targets before and after until-reward's switch leave the update's inputs alike, so
    only the recapture at the switch brings advantage learning into a graphed update."""
    kw = {
        "preset": "general",
        "blr__target": "mean",
        "k_target": "k",
        "blr__advantage_learning": 0.9,
        "blr__switch_restart": "none",
        "target_update_every": 25,
    }
    runs = []
    for setting in ("off", "on"):
        agent = _agent(tmp_path / setting, "farsighter", device="cuda", cuda_graph=setting, **kw)
        _feed(agent, 300)
        for step in range(1, 61):
            agent.learn(step)
        inner(agent).calibrate(restart=False)
        for step in range(61, 121):
            agent.learn(step)
        runs.append(agent)
    eager, graphed = runs
    assert inner(graphed).learner.step.captures >= 2
    for a, b in zip(_params(graphed), _params(eager), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5)
