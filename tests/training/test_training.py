"""The loop end to end: outputs, determinism, crash and resume, target network, loading."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import torch

import farsighter
from farsighter.agents import loop_class
from farsighter.agents.ddqn import DDQNAgent
from farsighter.errors import RunDirError
from farsighter.replay import VectorStep
from farsighter.rundir import CHECKPOINT_FILE, METRIC_COLUMNS
from tests.conftest import tiny


def metric_rows(run_dir: Path) -> list[dict[str, str]]:
    with (run_dir / "metrics.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        r.pop("SPS")  # wall-clock dependent
    return rows


def weights(run_dir: Path) -> dict[str, torch.Tensor]:
    state = torch.load(run_dir / "policy.pt", weights_only=False)["agent"]
    return state["q"] if "q" in state else state["torso"]


@pytest.mark.parametrize("algo", ["ddqn", "kddqn", "bdqn", "farsighter", "ob2i", "krnd"])
def test_run_directory_outputs(tmp_path: Path, algo: str) -> None:
    summary = farsighter.train(tiny(algo, tmp_path / "run"))
    run = Path(summary["run_dir"])
    for name in (
        "config.json",
        "metrics.csv",
        "eval.csv",
        CHECKPOINT_FILE,
        "policy.pt",
        "summary.json",
    ):
        assert (run / name).exists(), name
    assert any(p.name.startswith("events.out.tfevents") for p in run.iterdir())
    with (run / "metrics.csv").open() as fh:
        assert tuple(next(csv.reader(fh))) == METRIC_COLUMNS
    assert summary["global_step"] == 1_500 and summary["episodes"] > 0
    assert np.isfinite(summary["final_eval_return"])


@pytest.mark.parametrize("algo", ["ddqn", "farsighter", "ob2i", "krnd"])
def test_same_seed_same_run_on_cpu(tmp_path: Path, algo: str) -> None:
    farsighter.train(tiny(algo, tmp_path / "a", total_steps=1_000))
    farsighter.train(tiny(algo, tmp_path / "b", total_steps=1_000))
    assert metric_rows(tmp_path / "a") == metric_rows(tmp_path / "b")  # actions -> returns, losses
    wa, wb = weights(tmp_path / "a"), weights(tmp_path / "b")
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    farsighter.train(tiny(algo, tmp_path / "c", total_steps=1_000, seed=2))
    assert metric_rows(tmp_path / "a") != metric_rows(tmp_path / "c")


@pytest.mark.parametrize("algo", ["kddqn", "farsighter", "ob2i", "krnd"])
def test_crash_then_resume_equals_uninterrupted(
    tmp_path: Path, algo: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    full = tmp_path / "full"
    farsighter.train(tiny(algo, full))

    crashed = tmp_path / "crashed"
    agent_cls = loop_class(algo)  # the class the loop will use
    original = agent_cls.learn

    def learn_then_crash(self, global_step: int):  # type: ignore[no-untyped-def]
        if global_step == 1_200:
            raise KeyboardInterrupt  # killed after the checkpoint at 1,000
        return original(self, global_step)

    monkeypatch.setattr(agent_cls, "learn", learn_then_crash)
    with pytest.raises(KeyboardInterrupt):
        farsighter.train(tiny(algo, crashed))
    monkeypatch.setattr(agent_cls, "learn", original)
    with pytest.raises(RunDirError):
        farsighter.train(tiny(algo, crashed))  # never overwritten without --resume
    farsighter.train(tiny(algo, crashed, resume=True))

    assert metric_rows(full) == metric_rows(crashed)
    wf, wc = weights(full), weights(crashed)
    assert all(torch.equal(wf[k], wc[k]) for k in wf)


def _spaces():  # type: ignore[no-untyped-def]
    import gymnasium as gym

    env = gym.make("CartPole-v1")
    return env.observation_space, env.action_space


def test_resume_rejects_changed_config_and_corrupt_checkpoint(tmp_path: Path) -> None:
    run = tmp_path / "run"
    farsighter.train(tiny("ddqn", run, total_steps=600))
    with pytest.raises(RunDirError, match="different config"):
        farsighter.train(tiny("ddqn", run, total_steps=900, lr=0.1, resume=True))
    summary = farsighter.train(tiny("ddqn", run, total_steps=900, resume=True))  # longer budget
    assert summary["global_step"] == 900
    (run / CHECKPOINT_FILE).write_bytes(b"not a checkpoint")
    with pytest.raises(RunDirError, match="corrupt"):
        farsighter.train(tiny("ddqn", run, total_steps=1_200, resume=True))


def test_target_network_does_not_move_with_online_updates(tmp_path: Path) -> None:
    cfg = tiny("ddqn", tmp_path / "unused", target_update_every=10_000)
    obs_space, act_space = _spaces()
    agent = DDQNAgent([cfg], obs_space, act_space, frame_stack=1, device=torch.device("cpu"))
    rng = np.random.default_rng(0)
    for t in range(300):
        agent.observe(
            [
                VectorStep(
                    rng.normal(size=(1, 4)).astype(np.float32),
                    np.array([t % 2]),
                    np.array([1.0]),
                    np.array([t % 50 == 49]),
                    np.array([False]),
                    [rng.normal(size=4).astype(np.float32)] if t % 50 == 49 else None,
                )
            ]
        )
    before = {k: v.clone() for k, v in agent.loss.q_target.state_dict().items()}
    online_before = {k: v.clone() for k, v in agent.q.state_dict().items()}
    for _ in range(20):
        agent.update()
    assert any(not torch.equal(online_before[k], v) for k, v in agent.q.state_dict().items())
    assert all(torch.equal(before[k], v) for k, v in agent.loss.q_target.state_dict().items())
    agent.learn(10_000)  # the N-th step copies
    assert all(
        torch.equal(agent.q.state_dict()[k], v) for k, v in agent.loss.q_target.state_dict().items()
    )


def test_load_agent_acts_greedily(tmp_path: Path) -> None:
    summary = farsighter.train(tiny("farsighter", tmp_path / "run", total_steps=800))
    policy = farsighter.load_agent(summary["run_dir"])
    env = policy.make_env(seed=3)
    obs, _ = env.reset(seed=3)
    a1 = policy.act(obs[None])
    a2 = policy.act(obs[None])
    assert a1.shape == (1,) and a1[0] in (0, 1) and np.array_equal(a1, a2)


def test_vectorised_environments(tmp_path: Path) -> None:
    summary = farsighter.train(tiny("farsighter", tmp_path / "run", num_envs=3, total_steps=900))
    assert summary["global_step"] == 900 and summary["episodes"] > 0


@pytest.mark.parametrize(
    ("algo", "extra"),
    [
        ("ddqn", {}),
        ("kddqn", {}),
        ("farsighter", {"adaptive_k__enabled": True, "adaptive_k__variance_target": 1e9}),
        ("ob2i", {}),
        ("rnd", {}),
    ],
)
def test_resume_without_replay_refills_before_updating(
    tmp_path: Path, algo: str, extra: dict[str, object], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A checkpoint saved without its replay (the atari preset's default) resumes: the agent
    acts for learning_starts (200) steps to refill before its first update, and adaptive k's
    state comes back with the checkpoint."""
    from farsighter.rundir import load_checkpoint

    run = tmp_path / "run"
    farsighter.train(tiny(algo, run, total_steps=1_000, save_replay=False, **extra))
    saved = load_checkpoint(run)["agent"]
    agent_cls = loop_class(algo)  # the class the loop will use
    calls: list[int] = []
    original = agent_cls.update

    def counted(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(agent_cls, "update", counted)

    class Watch:
        seen: list[tuple[int, int, float]] = []

        def on_step(self, global_step: int, info: dict, agent) -> None:  # type: ignore[no-untyped-def,type-arg]
            self.seen.append((global_step, len(calls), agent.diagnostics().get("k", 0.0)))

        def on_finish(self, run_dir: Path, agent) -> None:  # type: ignore[no-untyped-def]
            pass

    watch = Watch()
    cfg = tiny(algo, run, total_steps=1_600, save_replay=False, resume=True, **extra)
    farsighter.train(cfg, callbacks=[watch])
    assert all(n == 0 for step, n, _ in watch.seen if step < 1_000 + 200)
    assert watch.seen[-1][1] > 0  # and it learns again afterwards
    if "adaptive_k__enabled" in extra:
        assert saved["counters"]["k"] > tiny(algo, run, **extra).k  # k moved before the save
        assert watch.seen[0][2] == saved["counters"]["k"]  # and came back with the checkpoint


def test_overlap_env_needs_environments_that_step_asynchronously(tmp_path: Path) -> None:
    import gymnasium as gym

    from farsighter.errors import ConfigError
    from farsighter.train import overlap_enabled

    sync = gym.vector.SyncVectorEnv([lambda: gym.make("CartPole-v1")])

    class Async:
        def step_async(self, actions: object) -> None: ...

        def step_wait(self) -> None: ...

    cpu, cuda = torch.device("cpu"), torch.device("cuda")
    assert not overlap_enabled("auto", sync, cuda) and not overlap_enabled("off", sync, cpu)
    assert overlap_enabled("auto", Async(), cuda) and not overlap_enabled("auto", Async(), cpu)
    assert overlap_enabled("on", Async(), cpu) and not overlap_enabled("off", Async(), cuda)
    with pytest.raises(ConfigError, match="overlap_env on needs environments"):
        overlap_enabled("on", sync, cpu)
    with pytest.raises(ConfigError, match="overlap_env on needs"):  # before the run dir exists
        farsighter.train(tiny("ddqn", tmp_path / "run", overlap_env="on"))
    assert not (tmp_path / "run").exists()
    sync.close()


@pytest.mark.parametrize("num_actions", [2, 3, 18])
def test_epsilon_draws_for_one_environment_are_numpys_array_draws(num_actions: int) -> None:
    """The scalar draws of one environment give the numbers of rng.random(1) and
    rng.integers(0, A, size=1), and leave the generator where those leave it."""
    from farsighter.exploration.epsilon import epsilon_draws

    mine, numpys = np.random.default_rng(3), np.random.default_rng(3)
    for _ in range(500):
        coins, actions = epsilon_draws(mine, num_actions, 1)
        assert coins.tolist() == numpys.random(1).tolist()
        assert actions.tolist() == numpys.integers(0, num_actions, size=1).tolist()
        assert actions.dtype == np.int64
    assert mine.bit_generator.state == numpys.bit_generator.state


@pytest.mark.parametrize("epsilon", [0.0, 0.3, 1.0])
def test_epsilon_greedy_for_one_environment_acts_as_the_array_path(epsilon: float) -> None:
    """One environment's scalar path of epsilon_greedy gives the actions of the array path
    (coins, random actions, np.where over the greedy ones), calls greedy() only when it acts
    greedily, and leaves the generator where the array path leaves it."""
    from farsighter.exploration.epsilon import epsilon_draws, epsilon_greedy

    mine, ref = np.random.default_rng(5), np.random.default_rng(5)
    calls = []

    def greedy() -> np.ndarray:
        calls.append(1)
        return np.array([len(calls) % 2], dtype=np.int64)

    for _ in range(300):
        before = len(calls)
        got = epsilon_greedy(mine, epsilon, 3, greedy, 1)
        coins, random_actions = epsilon_draws(ref, 3, 1)
        greedy_call = len(calls) > before
        assert greedy_call == (not bool(coins[0] < epsilon))
        want = random_actions if coins[0] < epsilon else np.array([len(calls) % 2])
        assert got.tolist() == want.tolist() and got.dtype == np.int64
    assert mine.bit_generator.state == ref.bit_generator.state
