"""The envpool Atari backend against the Gymnasium path: spaces, the SAME_STEP autoreset contract
(no transition across an episode boundary, envpool's post-terminal step never seen), zero-padded
stacks, whole-game statistics with unclipped rewards, and step-for-step identical trajectories."""

from __future__ import annotations

import importlib
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("envpool", reason="envpool tests need the envpool extra (installed by CI)")
pytest.importorskip("ale_py", reason="the Gymnasium reference needs the atari extra")

import gymnasium as gym  # noqa: E402

import farsighter  # noqa: E402
from farsighter.config import Config, make_config  # noqa: E402
from farsighter.envs import frame_stack_of, make_vector_env  # noqa: E402
from farsighter.envs.envpool_vec import (  # noqa: E402
    EnvpoolAtariVector,
    envpool_available,
    envpool_supports,
    envpool_task_id,
    make_envpool_atari,
)
from farsighter.errors import EnvError  # noqa: E402
from farsighter.replay import ReplayBuffer  # noqa: E402
from farsighter.session import final_observations, finished_episodes  # noqa: E402
from tests.conftest import inner


def envpool_of(cfg: Config, *, seed: int = 0, training: bool = True, **kw: Any) -> Any:
    """The envpool twin of ``make_vector_env(cfg)`` (the factory hook, spelled out)."""
    a = cfg.atari
    args: dict[str, Any] = dict(
        frame_skip=a.frame_skip,
        noop_max=a.noop_max,
        screen_size=a.screen_size,
        frame_stack=a.frame_stack,
        training=training,
        terminal_on_life_loss=a.terminal_on_life_loss,
        clip_rewards=a.clip_rewards,
        repeat_action_probability=a.repeat_action_probability,
    )
    args.update(kw)
    return make_envpool_atari(cfg.env, cfg.num_envs, seed, **args)


def test_task_ids_and_errors() -> None:
    assert envpool_available()
    assert envpool_task_id("ALE/Breakout-v5") == "Breakout-v5"
    assert envpool_task_id("BreakoutNoFrameskip-v4") == "Breakout-v5"
    assert envpool_supports("ALE/Pong-v5", 30) and not envpool_supports("ALE/Pong-v5", 0)
    assert not envpool_supports("ALE/NoSuchGame-v5", 30)
    assert envpool_task_id("ALE/TicTacToe3D-v5") == "TicTacToe3d-v5"  # spelled differently
    for bad in ("ALE/NoSuchGame-v5", "ALE/Breakout-ram-v5", "ALE/Ant-v5", "CartPole-v1"):
        with pytest.raises(EnvError) as err:
            envpool_task_id(bad)
        assert "\n" not in str(err.value)
    with pytest.raises(EnvError, match="noop_max >= 1"):  # envpool's noop_max=0 crashes
        envpool_of(make_config("ddqn", "ALE/Pong-v5", atari__noop_max=0))


def test_spaces_and_dtypes_match_the_gymnasium_path() -> None:
    cfg = make_config("ddqn", "ALE/Pong-v5", num_envs=2)
    ref, env = make_vector_env(cfg, seed=0), envpool_of(cfg)
    try:
        assert isinstance(env, EnvpoolAtariVector) and isinstance(env, gym.vector.VectorEnv)
        assert env.num_envs == ref.num_envs == 2
        for name in ("single_observation_space", "single_action_space"):
            assert getattr(env, name) == getattr(ref, name)
        assert env.observation_space == ref.observation_space
        assert env.action_space == ref.action_space
        assert env.metadata["autoreset_mode"] == ref.metadata["autoreset_mode"]
        (o1, i1), (o2, i2) = ref.reset(seed=0), env.reset(seed=0)
        assert o2.shape == o1.shape == (2, 4, 84, 84) and o2.dtype == o1.dtype == np.uint8
        assert (o2[:, :3] == 0).all()  # zero padding before the first frame
        assert np.array_equal(i1["lives"], i2["lives"])
        actions = np.array([0, 1])
        s1, s2 = ref.step(actions), env.step(actions)
        for a, b in zip(s1[1:4], s2[1:4], strict=True):
            assert a.dtype == b.dtype and a.shape == b.shape
    finally:
        ref.close()
        env.close()


@pytest.mark.parametrize("game", ["Pong", "Breakout"])
def test_first_observation_identical(game: str) -> None:
    # The same emulator frame after one no-op (noop_max=1 makes both take exactly one), the same
    # palette grey and cv2 INTER_AREA resize: measured 0.0 mean abs difference on Pong,
    # Breakout, SpaceInvaders, MsPacman and Seaquest, so exact equality is asserted.
    cfg = make_config("ddqn", f"ALE/{game}-v5", num_envs=1, atari__noop_max=1)
    ref, env = make_vector_env(cfg, seed=0), envpool_of(cfg)
    o1, _ = ref.reset(seed=0)
    o2, _ = env.reset(seed=0)
    ref.close()
    env.close()
    assert np.abs(o1.astype(int) - o2.astype(int)).mean() == 0.0


def test_step_for_step_identical_to_the_gymnasium_path() -> None:
    """Breakout with life-loss terminals, clipping and E=2: the same actions give the same
    observations, rewards, terminals, lives and whole-game statistics at every step, across
    life losses and game overs. Only a final observation of a game that ended inside a frame
    skip may differ (Gymnasium keeps the previous step's pooled frame there)."""
    e = 2
    cfg = make_config("ddqn", "ALE/Breakout-v5", num_envs=e, atari__noop_max=1)
    ref, env = make_vector_env(cfg, seed=0), envpool_of(cfg)
    o1, _ = ref.reset(seed=0)
    o2, _ = env.reset(seed=0)
    assert np.array_equal(o1, o2)
    rng = np.random.default_rng(0)
    ends = games = 0
    final_gaps: list[float] = []
    for _ in range(450):
        actions = rng.integers(0, 4, e)
        o1, r1, t1, u1, i1 = ref.step(actions)
        o2, r2, t2, u2, i2 = env.step(actions)
        assert np.array_equal(o1, o2)
        assert np.array_equal(r1, r2) and set(np.unique(r2)) <= {-1.0, 0.0, 1.0}
        assert np.array_equal(t1, t2) and np.array_equal(u1, u2)
        assert np.array_equal(i1["lives"], i2["lives"])
        assert [ep[:2] for ep in finished_episodes(i1)] == [ep[:2] for ep in finished_episodes(i2)]
        games += len(finished_episodes(i2))
        f1, f2 = final_observations(i1, e), final_observations(i2, e)
        assert (f1 is None) == (f2 is None)
        for a, b in zip(f1 or [], f2 or [], strict=True):
            assert (a is None) == (b is None)
            if b is not None:
                ends += 1
                final_gaps.append(float(np.abs(a.astype(int) - b.astype(int)).mean()))
    ref.close()
    env.close()
    assert games >= 2 and ends >= games + 4  # game overs and life-loss terminals were crossed
    assert np.mean(final_gaps) < 0.5 and sum(g > 0 for g in final_gaps) <= games


def test_episode_boundaries_without_the_post_terminal_step() -> None:
    """Evaluation flavour (no life loss, raw rewards) with a short time limit: each step either
    shifts the stack by one frame or starts a fresh zero-padded one; the steps of the ended
    episodes add up to the steps taken (envpool's reset step is never a transition), and each
    episode's return is the sum of its unclipped rewards."""
    e, limit = 2, 60
    cfg = make_config("ddqn", "ALE/SpaceInvaders-v5", num_envs=e)
    env = envpool_of(cfg, training=False, max_episode_steps=limit)
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(3)
    returns, lengths = np.zeros(e), np.zeros(e, dtype=int)
    done_lengths: list[int] = []
    big_reward = False
    for _ in range(3 * limit):
        nxt, rew, term, trunc, info = env.step(rng.integers(0, 6, e))
        returns += rew
        lengths += 1
        big_reward |= bool((rew > 1).any())
        final = final_observations(info, e)
        episodes = {
            int(i): ep
            for i, ep in zip(
                np.flatnonzero(info.get("final_info", {}).get("_episode", [])),
                finished_episodes(info),
                strict=True,
            )
        }
        for i in range(e):
            prev = obs[i]
            if term[i] or trunc[i]:
                assert final is not None and final[i] is not None
                assert np.array_equal(final[i][:-1], prev[1:])  # the ended episode's last stack
                assert (nxt[i][:-1] == 0).all() and nxt[i][-1].any()  # a fresh first stack
                assert not np.array_equal(nxt[i][-1], final[i][-1])
                assert episodes[i][0] == returns[i] and episodes[i][1] == lengths[i]
                assert bool(trunc[i]) == (lengths[i] == limit) and not (term[i] and trunc[i])
                done_lengths.append(int(lengths[i]))
                returns[i], lengths[i] = 0.0, 0
            else:
                assert np.array_equal(nxt[i][:-1], prev[1:])  # one frame later, same episode
                assert final is None or final[i] is None
        obs = nxt
    env.close()
    assert len(done_lengths) >= 2 * e and sum(done_lengths) + lengths.sum() == 3 * limit * e
    assert big_reward  # SpaceInvaders pays 5..30: the returns above are unclipped


def test_life_loss_ends_the_episode_not_the_game() -> None:
    cfg = make_config("ddqn", "ALE/Breakout-v5", num_envs=1)
    env = envpool_of(cfg, seed=1)
    _, info = env.reset(seed=1)
    lives, rng = int(info["lives"][0]), np.random.default_rng(1)
    for _ in range(400):
        obs, rew, term, trunc, info = env.step(rng.integers(0, 4, 1))
        if term[0]:
            break
    env.close()
    assert term[0] and not trunc[0]
    assert "episode" not in info["final_info"]  # the game goes on
    assert 0 < int(info["lives"][0]) < lives  # one life fewer, not a new game
    assert info["final_info"]["lives"][0] == info["lives"][0]
    assert (obs[0, :3] == 0).all() and obs[0, -1].any()  # the new life's first stack


def test_replay_rebuilds_the_stacks_the_agent_saw() -> None:
    e = 2
    cfg = make_config("ddqn", "ALE/Breakout-v5", num_envs=e)
    env = envpool_of(cfg, seed=1)
    buf = ReplayBuffer(2_000, (4, 84, 84), np.uint8, num_envs=e, frame_stack=frame_stack_of(cfg))
    obs, _ = env.reset(seed=1)
    seen, rng, ended = [], np.random.default_rng(0), 0
    for _ in range(400):
        actions = rng.integers(0, 4, e)
        nxt, rew, term, trunc, info = env.step(actions)
        final = final_observations(info, e)
        ended += 0 if final is None else sum(f is not None for f in final)
        buf.add(obs, actions, rew, term, trunc, final)
        seen.append(obs.copy())
        obs = nxt
    env.close()
    assert ended >= 2
    for stream in range(e):
        n = int(buf.count[stream])
        logical = np.arange(n)
        rows = logical[(buf.flags[stream, logical] & 4) == 0]
        got = buf.stacked_obs(np.full(len(rows), stream), rows)
        assert np.array_equal(got, np.stack([s[stream] for s in seen]))


def test_seeds_and_pickling() -> None:
    cfg = make_config("ddqn", "ALE/Breakout-v5", num_envs=2)
    env = envpool_of(cfg, seed=5)

    def run(seed: int) -> list[np.ndarray]:
        obs, _ = env.reset(seed=seed)
        out, rng = [obs], np.random.default_rng(0)
        for _ in range(40):
            out.append(env.step(rng.integers(0, 4, 2))[0])
        return out

    first, again = run(5), run(5)  # a reseed remakes the pool: the same games again
    assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    with pytest.raises(TypeError):  # checkpoints then resume with fresh episodes
        pickle.dumps(env)
    env.close()


def breakout_run(tiny_config: Any, run_dir: Path, **kw: Any) -> Config:
    """A short DDQN run on two Breakout games (the envpool factory hook set by the caller)."""
    return tiny_config(
        "ddqn",
        run_dir,
        env="ALE/Breakout-v5",
        num_envs=2,
        buffer_size=2_000,
        batch_size=8,
        train_every=4,
        eval_every=0,
        eval_episodes=1,
        eval_max_steps=50,
        device="cpu",
        **kw,
    )


def test_training_loop_runs_on_envpool(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tiny_config: Any
) -> None:
    # farsighter.train is also the name of the function, so fetch the module itself.
    train_module = importlib.import_module("farsighter.train")
    monkeypatch.setattr(
        train_module, "make_vector_env", lambda cfg, seed: envpool_of(cfg, seed=seed)
    )
    cfg = breakout_run(tiny_config, tmp_path / "run", total_steps=400, learning_starts=200)
    summary = farsighter.train(cfg)
    assert summary["global_step"] == 400 and summary["episodes"] >= 1


def test_the_factory_picks_the_backend_the_config_names() -> None:
    from farsighter.envs import make_vector_env
    from farsighter.envs.envpool_vec import EnvpoolAtariVector

    picked = {}
    for backend in ("auto", "envpool", "gymnasium"):
        cfg = make_config("ddqn", "ALE/Pong-v5", num_envs=2, **{"atari.backend": backend})
        envs = make_vector_env(cfg, seed=0)
        picked[backend] = isinstance(envs, EnvpoolAtariVector)
        envs.close()
    assert picked == {"auto": True, "envpool": True, "gymnasium": False}
    # auto falls back to Gymnasium where envpool cannot serve (no no-op starts)
    cfg = make_config("ddqn", "ALE/Pong-v5", **{"atari.noop_max": 0})
    envs = make_vector_env(cfg, seed=0)
    assert not isinstance(envs, EnvpoolAtariVector)
    envs.close()


def test_step_async_then_wait_is_the_same_step() -> None:
    """Two pools with one seed: one stepped by step(), the other by step_async + step_wait
    (life losses and game ends included), give the same observations, rewards and flags."""
    cfg = make_config("ddqn", "ALE/Breakout-v5", num_envs=3)
    a, b = envpool_of(cfg, max_episode_steps=80), envpool_of(cfg, max_episode_steps=80)
    oa, _ = a.reset(seed=5)
    ob, _ = b.reset(seed=5)
    assert np.array_equal(oa, ob)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(200):
        actions = rng.integers(0, 4, 3)
        ra = a.step(actions)
        b.step_async(actions)
        rb = b.step_wait()
        for x, y in zip(ra[:4], rb[:4], strict=True):
            assert np.array_equal(x, y)
        ended += int(np.sum(ra[2] | ra[3]))
    assert ended >= 3
    with pytest.raises(RuntimeError, match="without a step_async"):
        b.step_wait()
    b.step_async(np.zeros(3, int))
    with pytest.raises(RuntimeError, match="before step_wait"):
        b.step_async(np.zeros(3, int))
    b.reset(seed=6)  # collects the step in flight, then remakes the pool
    b.step(np.zeros(3, int))
    a.close()
    b.close()


def test_overlap_updates_while_the_games_step(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tiny_config: Any
) -> None:
    """overlap_env on: each vector step's updates come after step_async and before the step's
    transitions are stored; with no updates in the run, the replay is the same as without it."""
    train_module = importlib.import_module("farsighter.train")
    monkeypatch.setattr(
        train_module, "make_vector_env", lambda cfg, seed: envpool_of(cfg, seed=seed)
    )
    from farsighter.agents.ddqn import DDQNAgent

    events: list[str] = []
    replays: dict[str, Any] = {}
    for name in ("observe", "learn"):
        original = getattr(DDQNAgent, name)

        def spy(self: Any, *args: Any, _f: Any = original, _n: str = name) -> Any:
            events.append(_n)
            return _f(self, *args)

        monkeypatch.setattr(DDQNAgent, name, spy)

    class Keep:
        def on_step(self, global_step: int, info: Any, agent: Any) -> None:
            pass

        def on_finish(self, run_dir: Path, agent: Any) -> None:
            replays[run_dir.name] = inner(agent).replay

    def run(overlap: str, learning_starts: int) -> dict[str, Any]:
        events.clear()
        cfg = breakout_run(
            tiny_config,
            tmp_path / f"{overlap}{learning_starts}",
            total_steps=300,
            learning_starts=learning_starts,
            overlap_env=overlap,
        )
        return farsighter.train(cfg, callbacks=[Keep()])

    summary = run("on", 100)
    assert summary["global_step"] == 300
    assert events[:2] == ["learn", "observe"] and "observe" not in events[::2]
    run("on", 1_000)  # no updates: the order cannot change what is stored
    run("off", 1_000)
    assert events[:2] == ["observe", "learn"]
    on, off = replays["on1000"], replays["off1000"]
    assert np.array_equal(on.count, off.count) and np.array_equal(on.frames, off.frames)
    assert np.array_equal(on.actions, off.actions) and np.array_equal(on.flags, off.flags)
