"""Replay validity rules (Dopamine-style), k-step sampling, frame stacking and sizes."""

import numpy as np
import pytest

from farsighter.errors import ConfigError
from farsighter.replay import ReplayBuffer
from farsighter.replay.buffer import SLOT_ARRAYS

G = 0.5


def fill(buf: ReplayBuffer, episodes: list[tuple[int, str]], start: int = 0) -> int:
    """Episodes of given length ending by 'term' or 'trunc'; obs = global step id (flat, 1-d)."""
    step = start
    for length, end in episodes:
        for t in range(length):
            last = t == length - 1
            term = last and end == "term"
            trunc = last and end == "trunc"
            final = [np.array([step + 0.5], dtype=np.float32)] if last else None
            buf.add(
                np.array([[step]], dtype=np.float32),
                np.array([t % 3]),
                np.array([1.0]),
                np.array([term]),
                np.array([trunc]),
                final,
            )
            step += 1
    return step


def all_valid(buf: ReplayBuffer, k: int, stride: int = 1) -> np.ndarray:
    low = int(max(buf.count[0] - buf.capacity, 0, buf.floor[0]))
    starts = np.arange(low, int(buf.count[0]), dtype=np.int64)
    ok, _ = buf.valid_mask(np.zeros_like(starts), starts, k, stride)
    return starts[ok]


def test_one_step_transitions_and_final_row() -> None:
    buf = ReplayBuffer(100, (1,), np.float32)
    fill(buf, [(3, "term")])
    b = buf.sample_indices(np.zeros(3, np.int64), np.arange(3), k=1, gamma=G)
    assert list(b.obs[:, 0]) == [0, 1, 2]
    assert list(b.next_obs[:, 0]) == [1, 2, 2.5]  # last next obs is the stored final obs
    assert list(b.bootstrap) == [G, G, 0.0]
    assert 3 not in all_valid(buf, 1)  # the final row is never a start


def test_kstep_window_crossing_episode_end_stops_there() -> None:
    buf = ReplayBuffer(100, (1,), np.float32)
    fill(buf, [(3, "term"), (5, "trunc")])
    # episode 1: rows 0..2 (obs 0..2) + final row 3; episode 2: rows 4..8 (obs 3..7) + final row 9
    b = buf.sample_indices(np.zeros(2, np.int64), np.array([1, 6]), k=4, gamma=G)
    assert np.allclose(b.returns, [1 + G, 1 + G + G**2])
    assert list(b.steps) == [2, 3]
    assert np.allclose(b.bootstrap, [0.0, G**3])  # terminal: none; truncation: gamma^j
    assert np.allclose(b.next_obs[:, 0], [2.5, 7.5])  # truncation bootstraps from the real last obs


def test_write_cursor_incomplete_window_is_invalid() -> None:
    buf = ReplayBuffer(100, (1,), np.float32)
    for t in range(5):  # an episode still running: rows 0..4
        buf.add(
            np.array([[t]], np.float32),
            np.array([0]),
            np.array([1.0]),
            np.array([False]),
            np.array([False]),
        )
    assert list(all_valid(buf, 3)) == [0, 1]  # row 2 needs row 5 to bootstrap
    assert list(all_valid(buf, 1)) == [0, 1, 2, 3]  # the newest row has no next obs yet
    buf.add(
        np.array([[5]], np.float32),
        np.array([0]),
        np.array([1.0]),
        np.array([True]),
        np.array([False]),
        [np.array([5.5], np.float32)],
    )
    assert list(all_valid(buf, 3)) == [0, 1, 2, 3, 4, 5]  # the episode end completes them


def test_wraparound_overwritten_rows_are_never_used() -> None:
    buf = ReplayBuffer(8, (1,), np.float32)
    fill(buf, [(20, "trunc")])  # 21 rows written into 8 slots
    valid = all_valid(buf, 2)
    assert valid.min() >= 21 - 8
    b = buf.sample(64, k=2, gamma=G)
    assert (b.obs[:, 0] >= 13).all()  # only live rows
    expected_next = b.obs[:, 0] + b.steps
    expected_next = np.where(expected_next == 20, 19.5, expected_next)  # final row holds obs 19.5
    assert np.allclose(b.next_obs[:, 0], expected_next)


def test_stride_keeps_one_tuple_per_k_steps() -> None:
    buf = ReplayBuffer(200, (1,), np.float32)
    fill(buf, [(10, "term"), (7, "trunc")])
    starts = all_valid(buf, 3, stride=3)
    t = buf.t_ep[0, starts]
    assert (t % 3 == 0).all()
    assert len(starts) == 4 + 3  # ceil(10/3) + ceil(7/3): one tuple per k steps (Algorithm 1)


def test_recent_window_samples_only_latest_rows() -> None:
    buf = ReplayBuffer(1000, (1,), np.float32, seed=3)
    fill(buf, [(300, "trunc")])
    b = buf.sample(256, k=1, gamma=G, recent=50)
    assert (b.index >= 301 - 50).all()


def test_clear_forgets_previous_rows() -> None:
    buf = ReplayBuffer(1000, (1,), np.float32)
    n = fill(buf, [(30, "term")])
    buf.clear()
    with pytest.raises(ValueError):
        buf.sample(4, k=1, gamma=G)
    fill(buf, [(10, "term")], start=n)
    b = buf.sample(32, k=1, gamma=G)
    assert (b.index >= 31).all()


def test_impossible_sizes_are_refused() -> None:
    with pytest.raises(ConfigError):
        ReplayBuffer(0, (1,), np.float32)
    with pytest.raises(ConfigError):
        ReplayBuffer(3, (1,), np.float32, num_envs=4)
    with pytest.raises(ConfigError):
        ReplayBuffer(10, (3, 4), np.uint8, frame_stack=4)  # stack axis must match
    buf = ReplayBuffer(10, (1,), np.float32)
    fill(buf, [(5, "term")])
    with pytest.raises(ConfigError):
        buf.sample(2, k=1, recent=11)
    with pytest.raises(ConfigError):
        buf.sample(2, k=0)


def stack_episode(buf: ReplayBuffer, n_steps: int, start_id: int, end: str) -> list[np.ndarray]:
    """Frames carry their id; returns the stacked observations the acting side would see."""
    s = buf.frame_stack
    seen: list[np.ndarray] = []
    history: list[int] = []
    for t in range(n_steps + 1):
        history.append(start_id + t)
        frames = [0] * max(0, s - len(history)) + history[-s:]
        seen.append(np.stack([np.full((2, 2), f, np.uint8) for f in frames]))
    for t in range(n_steps):
        last = t == n_steps - 1
        buf.add(
            seen[t][None],
            np.array([0]),
            np.array([0.0]),
            np.array([last and end == "term"]),
            np.array([last and end == "trunc"]),
            [seen[t + 1]] if last else None,
        )
    return seen


def test_frame_stack_zero_pads_before_episode_start_and_wraps() -> None:
    buf = ReplayBuffer(12, (4, 2, 2), np.uint8, frame_stack=4)
    seen1 = stack_episode(buf, 5, 10, "term")  # rows 0..4, final 5
    seen2 = stack_episode(buf, 6, 50, "trunc")  # rows 6..11, final 12 (wraps)
    for logical, expected in [(6, seen2[0]), (7, seen2[1]), (9, seen2[3]), (12, seen2[6])]:
        got = buf.stacked_obs(np.array([0]), np.array([logical]))[0]
        # a terminal inside the stack window: frames of the previous episode are zeros
        assert np.array_equal(got, expected), logical
    # the first episode's oldest rows were overwritten: starts whose stack needs them are invalid
    assert 1 not in all_valid(buf, 1)
    del seen1


def test_multiple_streams_keep_episodes_apart() -> None:
    buf = ReplayBuffer(100, (1,), np.float32, num_envs=2, seed=0)
    for t in range(10):
        done = t == 4
        buf.add(
            np.array([[t], [100 + t]], np.float32),
            np.array([0, 1]),
            np.array([1.0, 2.0]),
            np.array([done, False]),
            np.array([False, False]),
            [np.array([t + 0.5], np.float32), None] if done else None,
        )
    b = buf.sample(64, k=3, gamma=G)
    stream1 = b.env_index == 1
    assert (b.obs[stream1, 0] >= 100).all() and (b.obs[~stream1, 0] < 100).all()
    assert np.allclose(b.returns[stream1], 2 * (1 + G + G**2))


def test_atari_bytes_per_transition_goal() -> None:
    cap = 10_000
    buf = ReplayBuffer(cap, (4, 84, 84), np.uint8, frame_stack=4)
    assert buf.nbytes / cap <= 7_100  # Dopamine stores 7,065; the floor is 84*84 = 7,056


def test_checkpoint_round_trip_samples_identically() -> None:
    a = ReplayBuffer(50, (1,), np.float32, seed=1)
    fill(a, [(30, "trunc"), (40, "term")])
    b = ReplayBuffer(50, (1,), np.float32, seed=99)
    b.load_state_dict(
        {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in a.state_dict().items()}
    )
    x, y = a.sample(16, k=3, gamma=G), b.sample(16, k=3, gamma=G)
    assert np.array_equal(x.index, y.index) and np.array_equal(x.returns, y.returns)


def test_checkpoint_holds_the_written_slots_and_loads_over_a_used_replay() -> None:
    """A replay larger than its run saves the slots written so far; loaded over a replay that
    holds other rows, it gives back the saved replay exactly (later slots zero again)."""
    a = ReplayBuffer(1_000, (1,), np.float32, num_envs=2, seed=1)
    for t in range(40):
        a.add(
            np.array([[t], [-t]], np.float32),
            np.array([0, 1]),
            np.array([1.0, 2.0]),
            np.array([False, False]),
            np.array([False, False]),
            None,
        )
    state = a.state_dict()
    assert state["frames"].shape == (2, 40, 1) and state["t_ep"].shape == (2, 40)
    used = ReplayBuffer(1_000, (1,), np.float32, num_envs=2, seed=5)
    fill_two = np.full((2, 1), 7.0, np.float32)
    for _ in range(300):
        used.add(
            fill_two,
            np.array([2, 2]),
            np.array([3.0, 3.0]),
            np.array([False, False]),
            np.array([True, True]),
            [fill_two[0], fill_two[1]],
        )
    used.load_state_dict(state)
    for key in ("frames", "actions", "rewards", "flags", "t_ep", "count", "floor"):
        assert np.array_equal(getattr(used, key), getattr(a, key)), key
    # a full replay saves every slot; a checkpoint of full arrays (older versions) loads
    full = ReplayBuffer(30, (1,), np.float32, seed=1)
    fill(full, [(45, "term")])
    assert full.state_dict()["frames"].shape == (1, 30, 1)
    big = ReplayBuffer(1_000, (1,), np.float32, seed=1)
    old = a.state_dict() | {k: getattr(a, k).copy() for k in SLOT_ARRAYS}
    with pytest.raises(ValueError, match="replay 'frames' has shape"):
        big.load_state_dict(old)  # two streams into one
    one = ReplayBuffer(1_000, (1,), np.float32, num_envs=2, seed=9)
    one.load_state_dict(old)
    assert np.array_equal(one.frames, a.frames)


@pytest.mark.parametrize("span", [[7], [3, 0, 5], [0, 4], [2, 2, 2, 9]])
def test_row_draws_are_generator_choice_without_its_checks(span: list[int]) -> None:
    """The sampler draws streams as Generator.choice(p=span / total) does, draw for draw, so
    replacing choice changed no minibatch (and no trained weight): streams and rows equal, and
    the generators end in the same state."""
    span_E = np.array(span, dtype=np.int64)
    low_E = np.arange(len(span), dtype=np.int64) * 100
    ours, ref = np.random.default_rng(11), np.random.default_rng(11)
    e_N, l_N = ReplayBuffer._draw_rows(low_E, span_E, 500, ours)
    e_ref = ref.choice(len(span), size=500, p=span_E / span_E.sum())
    l_ref = low_E[e_ref] + (ref.random(500) * span_E[e_ref]).astype(np.int64)
    np.testing.assert_array_equal(e_N, e_ref)
    np.testing.assert_array_equal(l_N, l_ref)
    assert e_N.dtype == np.int64 and ours.random() == ref.random()
    assert set(e_N.tolist()) == {i for i, s in enumerate(span) if s > 0}  # empty streams never


@pytest.mark.parametrize("stack", [1, 3])
def test_one_stream_fast_add_writes_the_rows_of_the_array_path(stack: int) -> None:
    """``add`` with one stream takes scalar indices (``_add_one``); every array it keeps, and
    every minibatch after, equals what the array path for any number of streams writes, over
    terminations, truncations and a wraparound."""
    shape = (stack, 2) if stack > 1 else (2,)
    fast = ReplayBuffer(23, shape, np.float32, frame_stack=stack, seed=3)
    ref = ReplayBuffer(23, shape, np.float32, frame_stack=stack, seed=3)
    assert fast.scalar_add
    ref.scalar_add = False  # the array path
    rng = np.random.default_rng(0)
    for t in range(60):
        obs = rng.normal(size=(1, *shape)).astype(np.float32)
        ends = rng.random(2) < 0.1
        final = [rng.normal(size=shape).astype(np.float32)] if ends.any() else None
        args = (obs, np.array([t % 3]), np.array([rng.normal()]), ends[:1], ends[1:], final)
        fast.add(*args)
        ref.add(*args)
    for name in ("frames", "actions", "rewards", "flags", "t_ep", "count", "episode_t"):
        assert np.array_equal(getattr(fast, name), getattr(ref, name)), name
        assert getattr(fast, name).dtype == getattr(ref, name).dtype, name
    a, b = fast.sample(32, k=3, gamma=G), ref.sample(32, k=3, gamma=G)
    assert np.array_equal(a.obs, b.obs) and np.array_equal(a.returns, b.returns)
    assert np.array_equal(a.next_obs, b.next_obs) and np.array_equal(a.bootstrap, b.bootstrap)


def test_cut_replay_bootstraps_from_the_state_of_the_first_exploratory_action() -> None:
    """A replay that cuts (k_target cut) forms the window up to the first exploratory action
    after the start and bootstraps from the observation it was taken at; the same rows without
    cutting form the full window. The scalar and the array add store the same flags."""
    from farsighter.replay.buffer import EXPLORATORY

    k, gamma = 4, 0.9
    for envs in (1, 2):
        cutting = ReplayBuffer(64, (1,), np.float32, num_envs=envs, cut_exploratory=True)
        plain = ReplayBuffer(64, (1,), np.float32, num_envs=envs)
        assert cutting.scalar_add == (envs == 1)
        explored = [False, False, False, True, False, False, False, False]
        for t, flag in enumerate(explored):
            for rb in (cutting, plain):
                rb.add(
                    np.full((envs, 1), t, np.float32),
                    np.zeros(envs, np.int32),
                    np.ones(envs),
                    np.zeros(envs, bool),
                    np.zeros(envs, bool),
                    None,
                    np.full(envs, flag),
                )
        assert ((cutting.flags[0, :8] & EXPLORATORY) != 0).tolist() == explored
        start = np.array([1, 2, 3])
        e = np.zeros(3, np.int64)
        batch = cutting.gather(e, start, k, gamma)
        # from row 1 the action at row 3 is exploratory: rows 1, 2 summed, bootstrap from s_3
        assert batch.steps.tolist() == [2, 1, 4]  # row 3's own flag does not cut its window
        assert batch.next_obs[:, 0].tolist() == [3.0, 3.0, 7.0]
        np.testing.assert_allclose(batch.returns, [1 + gamma, 1, 1 + gamma + gamma**2 + gamma**3])
        np.testing.assert_allclose(batch.bootstrap, [gamma**2, gamma, gamma**4], rtol=1e-6)
        full = plain.gather(e, start, k, gamma)
        assert full.steps.tolist() == [4, 4, 4]
