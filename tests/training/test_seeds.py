"""Seeds in one process (issue #27 item 2): a seed trained in a batch is the run it is alone.

Every claim of :mod:`farsighter.seeds` is checked against :func:`farsighter.train.train` run
alone on the same config and seed: the weights, the optimizer state, the generators, the counters
and the logged files, bit for bit on CPU; a checkpoint that moves between the two; and the pieces
(the batched linear layer, the seed replay) against what they replace.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
import torch.nn.functional as F

from farsighter.agents import farsighter as farsighter_agent
from farsighter.algorithms import seed_batched
from farsighter.cli import main
from farsighter.config.presets import PREVIOUS_GENERAL_FARSIGHTER
from farsighter.errors import ConfigError
from farsighter.networks import QNetwork
from farsighter.replay import ReplayBuffer
from farsighter.replay.seeds import SeedReplay
from farsighter.seeds import batchable, seed_configs, train_seeds
from farsighter.stacked import StackedQNetwork, certain_argmax, stacked_linear
from farsighter.train import train

SEEDS = (3, 5, 8)
S45 = {key.replace(".", "__"): value for key, value in PREVIOUS_GENERAL_FARSIGHTER.items()}
"""Session 45's general Farsighter (its switch at the first reward), which the switch cases use."""


def _files(run: Path) -> dict[str, list[str]]:
    """The logged rows without the wall-clock columns (SPS differs between any two runs)."""
    out = {}
    for name in ("metrics.csv", "eval.csv"):
        rows = (run / name).read_text().splitlines()
        header = rows[0].split(",")
        keep = [i for i, col in enumerate(header) if col != "SPS"]
        out[name] = [",".join(row.split(",")[i] for i in keep) for row in rows]
    return out


@pytest.mark.parametrize(
    ("algo", "env", "values"),
    [
        ("ddqn", "CartPole-v1", {}),
        # k-step returns, a loss and clipping that bite, the RMSProp of Table 1, two envs a seed
        (
            "ddqn",
            "CartPole-v1",
            {"k": 3, "loss": "mse", "max_grad_norm": 0.5, "optimizer": "rmsprop", "num_envs": 2},
        ),
        ("ddqn", "farsighter/DeepSea6-v0", {"batch_size": 24}),
        # the defaults: k = 10 with the cut target, the targets' posterior noise, centred, a
        # draw held for k
        ("farsighter", "CartPole-v1", {"preset": "general"}),
        # fixed random features beside the learned ones (each seed's random layer, stacked),
        # the targets' draw at half the posterior's width
        (
            "farsighter",
            "farsighter/DeepSea6-v0",
            {
                "preset": "general",
                "blr__random_features": 48,
                "blr__target_noise_scale": 0.5,
                "batch_size": 24,
            },
        ),
        # held draws redrawn on a revisit, two envs a seed, clipping that bites, k = 3, over the
        # learned features alone, the k-step or one-step target chosen by the posterior mean,
        # the draw of the greedy action alone in the targets (a product per action present)
        (
            "farsighter",
            "farsighter/DeepSea6-v0",
            {
                "preset": "general",
                "blr__random_features": 0,
                "k": 3,
                "k_target": "max-mean",
                "blr__target": "sample-greedy",
                "num_envs": 2,
                "max_grad_norm": 0.5,
                "blr__redraw": "revisit",
                "batch_size": 24,
            },
        ),
        # Table 1's control column: batch-mode refreshes over each seed's latest tuples, the
        # recent window, k = 10, each seed's target cache over its own streams (two a seed),
        # and the acting draws widened to each seed's own action gaps (its prior sigma is 0.1)
        ("farsighter", "CartPole-v1", {"num_envs": 2, "blr__act_width": "action-gap"}),
        # BDQN of the control column: a refit from each seed's own replay every 400 steps, on
        # the steps of a target copy too (the refit reads the target torso before the copy)
        (
            "bdqn",
            "farsighter/DeepSea6-v0",
            {"blr__posterior_sampling": "uniform", "target_update_every": 400},
        ),
        # the default's targets until each seed's own first reward, then the mean's target cut
        # before exploratory actions (each seed's streams switch on their own)
        (
            "farsighter",
            "farsighter/Chain8-v0",
            {
                **S45,
                "preset": "general",
                "blr__optimism": "until-reward",
                "blr__calibrated_k_target": "cut",
                "blr__switch_restart": "none",  # the targets kept (the next case restarts)
                "k": 3,
                "learning_starts": 100,
                "batch_size": 24,
            },
        ),
        # the switch with the posterior refitted to each seed's own replay (its streams, cut
        # before its exploratory actions, through its own torsos; blr.switch_restart refit,
        # which restarts from the prior first) and the target cut after it
        (
            "farsighter",
            "farsighter/Chain8-v0",
            {
                **S45,
                "preset": "general",
                "blr__switch_restart": "refit",
                "k": 3,
                "learning_starts": 100,
                "batch_size": 24,
            },
        ),
        # advantage learning after each seed's switch, from the batch's target torsos
        (
            "farsighter",
            "farsighter/Chain8-v0",
            {
                **S45,
                "preset": "general",
                "blr__switch_restart": "refit-zero",
                "blr__advantage_learning": 0.9,
                "k": 3,
                "learning_starts": 100,
                "batch_size": 24,
            },
        ),
        # a uniformly random action, from each seed's own generator, where its episode is back
        # at a state it visited (the drifting lock: a wrong move goes one state back), in an
        # episode after one of that seed's that paid nothing
        (
            "farsighter",
            "farsighter/DriftChain8-v0",
            {"preset": "general", "blr__revisit_action": "uniform-unpaid", "k": 3},
        ),
        # windows cut before exploratory actions from the start, where they cost more than two
        # steps of delay (the Chain8 case above cuts at every one)
        (
            "farsighter",
            "farsighter/DeepSea6-v0",
            {"preset": "general", "k_target": "cut", "k": 3, "blr__cut_delay": 2.0},
        ),
        # the general preset's default: the plain k-step target, the targets' draws centred on
        # each seed's own minibatch
        ("farsighter", "farsighter/DeepSea6-v0", {"preset": "general", "k": 3, "batch_size": 24}),
        # RND: each seed's bonus (its networks, Adam, whitening and reward statistics)
        ("rnd", "CartPole-v1", {"preset": "general"}),
        # k-step intrinsic returns over windows cut by episode ends, two envs a seed
        ("krnd", "farsighter/DeepSea6-v0", {"num_envs": 2, "batch_size": 24}),
        # the BDQN code's targets: the acting draw's argmax, the max regression target, Huber
        (
            "bdqn",
            "CartPole-v1",
            {
                "preset": "general",
                "blr__target": "thompson",
                "blr__posterior_target": "max",
                "loss": "huber",
            },
        ),
    ],
)
def test_a_seed_in_a_batch_trains_as_it_does_alone(
    tmp_path: Path, tiny_config: Any, algo: str, env: str, values: dict[str, Any]
) -> None:
    cfg = tiny_config(algo, tmp_path / "batch", env=env, **values)
    assert batchable(cfg)
    summaries = train_seeds(seed_configs(cfg, SEEDS))
    assert [s["seed"] for s in summaries] == list(SEEDS)
    for seed in (SEEDS[0], SEEDS[-1]):
        alone_dir = tmp_path / f"alone{seed}"
        train(dataclasses.replace(cfg, seed=seed, run_dir=str(alone_dir)))
        batch_dir = tmp_path / "batch" / f"s{seed}"
        for name in ("policy.pt", "checkpoint.pt"):
            _same_states(_agent_state(alone_dir / name), _agent_state(batch_dir / name))
        assert _files(alone_dir) == _files(batch_dir)
    if {"blr__optimism", "blr__switch_restart"} & values.keys():  # each seed switched on its own
        steps = [
            _agent_state(tmp_path / "batch" / f"s{seed}" / "checkpoint.pt")["calibrated"]
            for seed in SEEDS
        ]
        assert any(steps), steps
    if values.get("blr__act_width") and "blr__optimism" not in values:  # (the act-width case)
        # each seed's own factor, widening its draws
        scales = [
            _agent_state(tmp_path / "batch" / f"s{seed}" / "checkpoint.pt")["head"]["act_scale"]
            for seed in SEEDS
        ]
        assert min(scales) > 1.0 and len(set(scales)) == len(SEEDS), scales
    # the seeds are different runs
    first = _agent_state(tmp_path / "batch" / f"s{SEEDS[0]}" / "policy.pt")
    second = _agent_state(tmp_path / "batch" / f"s{SEEDS[1]}" / "policy.pt")
    net = "torso" if "bdqn" in algo or "far" in algo else "q"
    for name in first[net]:  # the first layer (of the learned torso) and the random layer
        if name.endswith(("net.0.weight", "head.weight", "rf_weight")):
            assert not torch.equal(first[net][name], second[net][name]), name


def _same_states(alone: Any, batch: Any, where: str = "agent") -> None:
    """Two checkpoints' agent states equal, every tensor, array and value, key for key."""
    if isinstance(alone, dict):
        assert alone.keys() == batch.keys(), where
        for key in alone:
            _same_states(alone[key], batch[key], f"{where}.{key}")
    elif isinstance(alone, torch.Tensor):
        assert torch.equal(alone, batch), where
    elif isinstance(alone, np.ndarray):
        assert np.array_equal(alone, batch), where
    elif isinstance(alone, list | tuple):
        assert len(alone) == len(batch), where
        for i, (a, b) in enumerate(zip(alone, batch, strict=True)):
            _same_states(a, b, f"{where}[{i}]")
    elif dataclasses.is_dataclass(alone):  # a record (OB2I's episode): field by field
        _same_states(vars(alone), vars(batch), where)
    elif isinstance(alone, float) and np.isnan(alone):
        assert np.isnan(batch), where
    else:
        assert alone == batch, where


def test_settings_a_batch_cannot_take_train_alone(tmp_path: Path, tiny_config: Any) -> None:
    """Farsighter's batch refuses what it does not stack (its seeds then step together, each its
    own agent)."""
    base = tiny_config("farsighter", tmp_path, preset="general", blr__random_features=0)
    cfg = tiny_config("farsighter", tmp_path, preset="general", adaptive_k__enabled=True)
    assert "adaptive k" in farsighter_agent.supports(cfg, _box(), torch.device("cpu"))
    assert not batchable(cfg)
    assert farsighter_agent.supports(base, _box(), torch.device("cpu")) == ""
    wide = tiny_config("farsighter", tmp_path, preset="general", blr__random_features=64)
    assert wide.blr.random_features and batchable(wide)  # random features stack
    image = gym.spaces.Box(0, 255, (4, 84, 84), np.uint8)
    assert "image" in farsighter_agent.supports(base, image, torch.device("cpu"))
    assert "ob2i" not in seed_batched() and not batchable(tiny_config("ob2i", tmp_path))


@pytest.mark.parametrize(
    ("algo", "env", "values"),
    [
        ("ob2i", "CartPole-v1", {}),  # no seed-axis form
        ("naf", "Pendulum-v1", {"preset": "continuous", "batch_size": 16}),
        ("farsighter", "CartPole-v1", {"adaptive_k__enabled": True, "k": 3}),  # refused
    ],
)
def test_seeds_that_cannot_batch_step_together_each_as_it_runs_alone(
    tmp_path: Path, tiny_config: Any, algo: str, env: str, values: dict[str, Any], capsys: Any
) -> None:
    """One agent per seed, stepped together by the one loop (``Each``): each seed's files and
    agent are its run alone's."""
    cfg = tiny_config(algo, tmp_path / "together", env=env, total_steps=800, **values)
    assert not batchable(cfg)
    train_seeds(seed_configs(cfg, (1, 2)))
    assert "seeds step together" in capsys.readouterr().err
    for seed in (1, 2):
        alone_dir = tmp_path / f"alone{seed}"
        train(dataclasses.replace(cfg, seed=seed, run_dir=str(alone_dir)))
        together = tmp_path / "together" / f"s{seed}"
        _same_states(
            _agent_state(alone_dir / "checkpoint.pt"), _agent_state(together / "checkpoint.pt")
        )
        assert _files(alone_dir) == _files(together)


def _box() -> gym.spaces.Box:
    return gym.spaces.Box(-1.0, 1.0, (4,), np.float32)


def _agent_state(path: Path) -> dict[str, Any]:
    state = torch.load(path, weights_only=False)
    return state["agent"] if "agent" in state else state


@pytest.mark.parametrize(
    ("algo", "values"),
    [
        ("ddqn", {"k": 2}),
        ("farsighter", {"preset": "general", "k": 3}),  # its random features resume with it
        ("rnd", {"preset": "general"}),
    ],
)
def test_a_batch_killed_midway_resumes_in_a_batch_or_alone(
    tmp_path: Path, tiny_config: Any, algo: str, values: dict[str, Any]
) -> None:
    """Stopped at 1,000 of 1,500 steps (checkpoints every 500): seed 3 resumed alone and seeds 5
    and 8 resumed as a batch end where the uninterrupted batch ends, replay included."""
    full = tiny_config(algo, tmp_path / "full", **values)
    train_seeds(seed_configs(full, SEEDS))
    part = dataclasses.replace(full, run_dir=str(tmp_path / "part"), total_steps=1_000)
    train_seeds(seed_configs(part, SEEDS))
    resumed = dataclasses.replace(part, total_steps=1_500, resume=True)
    configs = seed_configs(resumed, SEEDS)
    train(configs[0])
    train_seeds(configs[1:])
    for seed in SEEDS:
        a = torch.load(tmp_path / "full" / f"s{seed}" / "checkpoint.pt", weights_only=False)
        b = torch.load(tmp_path / "part" / f"s{seed}" / "checkpoint.pt", weights_only=False)
        _same_states(a["agent"], b["agent"])
        for key, value in a["agent"]["replay"].items():
            other = b["agent"]["replay"][key]
            assert value == other if key == "rng" else np.array_equal(value, other), key


def test_seeds_at_different_steps_resume_in_groups(tmp_path: Path, tiny_config: Any) -> None:
    """A kill between two seeds' saves leaves them at different steps: each continues from its
    own checkpoint, and both end as the uninterrupted runs end."""
    cfg = tiny_config("ddqn", tmp_path / "runs", total_steps=1_000)
    short, long_ = (
        seed_configs(cfg, [3]),
        seed_configs(dataclasses.replace(cfg, total_steps=1_500), [5]),
    )
    train_seeds(short)
    train_seeds(long_)
    both = seed_configs(dataclasses.replace(cfg, total_steps=1_500, resume=True), [3, 5])
    train_seeds(both)
    full = seed_configs(
        dataclasses.replace(cfg, total_steps=1_500, run_dir=str(tmp_path / "full")), [3, 5]
    )
    train_seeds(full)
    for seed in (3, 5):
        _same_states(
            _agent_state(tmp_path / "full" / f"s{seed}" / "policy.pt"),
            _agent_state(tmp_path / "runs" / f"s{seed}" / "policy.pt"),
        )


def test_seed_configs_refuse_repeats_and_nothing() -> None:
    from farsighter import make_config

    cfg = make_config("ddqn", "CartPole-v1")
    with pytest.raises(ConfigError, match="twice"):
        seed_configs(cfg, [1, 2, 1])
    with pytest.raises(ConfigError, match="at least one"):
        seed_configs(cfg, [])
    assert [c.run_dir for c in seed_configs(dataclasses.replace(cfg, run_dir="x"), [4])] == ["x/s4"]


def test_cli_trains_seeds_into_their_own_directories(tmp_path: Path, capsys: Any) -> None:
    args = ["train", "--algo", "ddqn", "--env", "CartPole-v1", "--total-steps", "400"]
    args += ["--learning-starts", "100", "--eval-episodes", "1", "--no-progress"]
    args += ["--run-dir", str(tmp_path / "r"), "--seeds", "1", "2"]
    assert main(args) == 0
    assert (tmp_path / "r" / "s1" / "policy.pt").is_file()
    assert (tmp_path / "r" / "s2" / "policy.pt").is_file()
    assert main([*args[:-3], "--seeds", "1", "x"]) == 2
    assert "--seeds" in capsys.readouterr().err
    more = ["train", "--run-dir", str(tmp_path / "r"), "--resume", "--total-steps", "600"]
    assert main([*more, "--seeds", "1", "2"]) == 0
    for seed in (1, 2):
        summary = (tmp_path / "r" / f"s{seed}" / "summary.json").read_text()
        assert '"global_step": 600' in summary


@pytest.mark.parametrize("rows", [1, 2, 3, 16, 64, 128])
def test_stacked_linear_is_f_linear_per_seed(rows: int) -> None:
    """Forward and the three gradients of each seed's slice equal F.linear's alone, bit for bit,
    over layer shapes from a 4-wide input to deep sea's one-hot 400 and heads of 2 to 128 outputs
    (small products take another kernel on CPU: stacked.SMALL_PRODUCT)."""
    g = torch.Generator().manual_seed(rows)
    S = 3
    for inp in (4, 8, 30, 84, 120, 159, 400):
        for out in (2, 3, 5, 16, 64, 84, 128):
            shapes = ((S, rows, inp), (S, out, inp), (S, out))
            x, w, b = (torch.randn(*shape, generator=g) for shape in shapes)
            dy = torch.randn(S, rows, out, generator=g)
            xs, ws, bs = (t.clone().requires_grad_() for t in (x, w, b))
            y = stacked_linear(xs, ws, bs)
            (y * dy).sum().backward()
            with torch.no_grad():
                assert torch.equal(stacked_linear(x, w, b), y.detach())
            for s in range(S):
                xa, wa, ba = (t[s].clone().requires_grad_() for t in (x, w, b))
                ya = F.linear(xa, wa, ba)
                (ya * dy[s]).sum().backward()
                where = (rows, inp, out, s)
                assert torch.equal(y[s], ya), where
                assert torch.equal(xs.grad[s], xa.grad), where
                assert torch.equal(ws.grad[s], wa.grad), where
                assert torch.equal(bs.grad[s], ba.grad), where


def test_stacked_greedy_actions_are_each_network_alones() -> None:
    """Each seed's greedy actions from the stacked networks (the head's small product batched,
    its argmax kept where certain) are its network's alone, over inputs of magnitudes 1e-3 to
    1e2 and heads whose two rows nearly tie (the batched kernel and F.linear may rank those
    otherwise): those rows are never certain and take F.linear, the rest are."""
    S, A, obs_space = 8, 2, gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
    nets = []
    for s in range(S):
        torch.manual_seed(s)
        nets.append(QNetwork(obs_space, A, (120, 84)))
    with torch.no_grad():  # seeds 0-3: rows 0 and 1 equal but for a last bit of one weight
        for net in nets[:4]:
            head = net.head
            head.weight[1].copy_(head.weight[0])
            head.bias[1].copy_(head.bias[0])
            head.weight[1, 0] = torch.nextafter(head.weight[0, 0], torch.tensor(1.0))
    stacked = StackedQNetwork(nets)
    g = torch.Generator().manual_seed(0)
    uncertain = 0
    for scale in (1e-3, 1e-1, 1.0, 1e2):
        for _ in range(50):
            obs = torch.randn(S, 4, generator=g) * scale
            with torch.inference_mode():
                got = stacked.greedy(obs)
                alone = [int(net(obs[s : s + 1]).argmax(dim=1)) for s, net in enumerate(nets)]
                h = stacked._hidden(obs.view(S, 1, 4), None)
                _, sure = certain_argmax(h, *stacked._params[-2:])
            assert got.tolist() == alone
            uncertain += int((~sure[:4]).sum())
            assert bool(sure[4:].all())  # the networks whose rows are apart: batched
    assert uncertain == 4 * 200  # the near ties: every one taken from F.linear


def test_seed_replay_samples_each_seed_as_its_replay_alone() -> None:
    """Three seeds, two streams each, episodes of random lengths ended by terminations and
    truncations, k = 3 windows from a recent window: each seed's rows are the rows its replay
    alone samples, and its checkpoint is that replay's."""
    seeds, E, cap = [11, 12, 13], 2, 300
    seed_replay = SeedReplay(seeds, cap, (3,), np.float32, num_envs=E)
    alone = [ReplayBuffer(cap, (3,), np.float32, num_envs=E, seed=s) for s in seeds]
    rng = np.random.default_rng(0)
    for _ in range(400):
        obs = rng.standard_normal((len(seeds), E, 3)).astype(np.float32)
        act = rng.integers(0, 4, (len(seeds), E))
        rew = rng.standard_normal((len(seeds), E))
        term, trunc = rng.random((len(seeds), E)) < 0.05, rng.random((len(seeds), E)) < 0.03
        final = [
            [o if (t or u) else None for o, t, u in zip(obs[s], term[s], trunc[s], strict=True)]
            for s in range(len(seeds))
        ]
        for s, replay in enumerate(alone):
            replay.add(obs[s], act[s], rew[s], term[s], trunc[s], final[s])
        seed_replay.add(
            obs.reshape(-1, 3),
            act.reshape(-1),
            rew.reshape(-1),
            term.reshape(-1),
            trunc.reshape(-1),
            [o for f in final for o in f],
        )
    for _ in range(3):
        batch = seed_replay.sample_seeds(20, k=3, gamma=0.9, recent=200)
        for s, replay in enumerate(alone):
            own = replay.sample(20, k=3, gamma=0.9, recent=200)
            rows = slice(20 * s, 20 * (s + 1))
            assert np.array_equal(batch.env_index[rows] - s * E, own.env_index)
            for name in ("obs", "next_obs", "actions", "returns", "bootstrap", "index"):
                assert np.array_equal(getattr(batch, name)[rows], getattr(own, name)), name
    for s, replay in enumerate(alone):
        mine, theirs = seed_replay.member_state(s), replay.state_dict()
        assert mine.keys() == theirs.keys()
        for key in theirs:
            assert (
                mine[key] == theirs[key] if key == "rng" else np.array_equal(mine[key], theirs[key])
            )
    again = SeedReplay(seeds, cap, (3,), np.float32, num_envs=E)
    for s, replay in enumerate(alone):
        again.load_member(s, replay.state_dict())
    assert np.array_equal(again.frames, seed_replay.frames)
    assert np.array_equal(again.count, seed_replay.count)


def test_a_study_batches_the_seeds_of_ddqn_and_its_runs_are_those_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The maze study (its probe callback included) trains the two seeds of DDQN, BDQN (refits
    from the replay) and Farsighter (the target cache of its recent window) as one batch each and
    OB2I's one after another; every file of every run equals the study run job by job. With two
    workers and one agent's three seeds, the batches are of two and one (no core left idle)."""
    from farsighter.studies import maze, runner

    args = ["--steps", "1200", "--seeds", "1", "2", "--workers", "1", "--no-progress"]
    args += ["--agents", "DDQN", "BDQN", "Farsighter (k=10)", "OB2I"]
    settings = runner.settings_from(maze.STUDY, runner.parse(maze.STUDY, args))
    jobs = maze.STUDY.grid(settings)
    groups = runner.seed_batches(maze.STUDY, settings, tmp_path / "x", jobs)
    assert sorted([(j.label, j.seed) for j in g] for g in groups) == [
        [("BDQN", 1), ("BDQN", 2)],
        [("DDQN", 1), ("DDQN", 2)],
        [("Farsighter (k=10)", 1), ("Farsighter (k=10)", 2)],
        [("OB2I", 1)],
        [("OB2I", 2)],
    ]
    three = ["--seeds", "1", "2", "3", "--workers", "2", "--agents", "DDQN"]
    spread = runner.settings_from(maze.STUDY, runner.parse(maze.STUDY, three))
    split = runner.seed_batches(maze.STUDY, spread, tmp_path / "x", maze.STUDY.grid(spread))
    assert [[j.seed for j in g] for g in split] == [[1, 2], [3]]
    alone = runner.seed_batches(maze.STUDY, spread, tmp_path / "x", maze.STUDY.grid(spread), 1)
    assert [[j.seed for j in g] for g in alone] == [[1], [2], [3]]
    assert main(["maze", *args, "--seeds-per-batch", "0", "--out", str(tmp_path / "no")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--seeds-per-batch must be >= 1" in err[0], err
    assert not (tmp_path / "no").exists()
    assert main(["maze", *args, "--out", str(tmp_path / "batched")]) == 0
    assert main(["maze", *args, "--seeds-per-batch", "1", "--out", str(tmp_path / "alone")]) == 0
    for run in ("ddqn__s1", "bdqn__s1", "bdqn__s2", "farsighter-k-10__s1", "farsighter-k-10__s2"):
        a, b = tmp_path / "alone" / "runs" / run, tmp_path / "batched" / "runs" / run
        assert (a / "probe.csv").read_text() == (b / "probe.csv").read_text(), run
        assert _files(a) == _files(b), run
        _same_states(_agent_state(a / "policy.pt"), _agent_state(b / "policy.pt"))
