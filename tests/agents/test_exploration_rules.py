"""The exploration rule docs/design.md adds as its example is code that works: its block runs,
registers a schedule, and a run trains with it, holding each draw as the rule says."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import torch

from farsighter.exploration import SCHEDULES
from tests.conftest import parts, tiny

DESIGN = Path(__file__).resolve().parents[2] / "docs" / "design.md"


def _example() -> str:
    text = DESIGN.read_text()
    section = text[text.index("## Adding an exploration rule") :]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)  # type: ignore[union-attr]


def test_the_documented_rule_is_under_60_lines_and_holds_draws_as_it_says(tmp_path: Path) -> None:
    code = _example()
    assert len(code.strip().splitlines()) < 60
    exec(compile(code, str(DESIGN), "exec"), {})
    try:
        assert "episode-or-t" in SCHEDULES
        from farsighter.agents import build_agent

        cfg = tiny(
            "farsighter",
            tmp_path,
            learning_starts=0,
            **{"blr.redraw": "episode-or-t", "blr.redraw_every": 5, "blr.prior_std": 10.0},
        )
        import gymnasium as gym

        env = gym.make("CartPole-v1")
        agent = build_agent(
            cfg, env.observation_space, env.action_space, frame_stack=1, device=torch.device("cpu")
        )
        obs = np.full((1, 4), 0.3, np.float32)
        for _ in range(12):  # draws at steps 1, 6, 11: held for T = 5 steps each
            agent.act(obs, 10)
        assert parts(agent).counters.draws == 3
        # a whole run with it, resumed from its checkpoint at step 500 as the loop does
        from farsighter.train import train

        run = tiny(
            "farsighter", tmp_path / "run", total_steps=600, **{"blr.redraw": "episode-or-t"}
        )
        summary = train(run)
        assert summary["global_step"] == 600
        resumed = tiny(
            "farsighter", tmp_path / "run", total_steps=800, resume=True,
            **{"blr.redraw": "episode-or-t"},
        )  # fmt: skip
        assert train(resumed)["global_step"] == 800
    finally:
        SCHEDULES.pop("episode-or-t", None)
