"""Regenerate the published study results under docs/results/ from the current code.

    python scripts/results.py --list              # what it makes, and what each took last
    python scripts/results.py                     # all of them (about 3.5 hours on 2 cores)
    python scripts/results.py --only maze k-study # some of them

Each study runs into ``results-build/<folder>`` (resumable: an interrupted call continues
where it stopped, so the long ones can be run in parts), then its outputs (report, tables,
figures, study.json with the commit that made it, and the small files of its runs: no
checkpoints, policies, replays or TensorBoard files) replace ``docs/results/<folder>``. The wall
time of each study (summed over the calls that ran parts of it) is written to
``docs/results/walltimes.json``, and the table of docs/results/README.md is rewritten from this
list and those times.
"""

from __future__ import annotations

import argparse
import json
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"
BUILD = ROOT / "results-build"
TIMES = RESULTS / "walltimes.json"
KEEP = (".csv", ".json", ".md", ".png", ".npy")  # a study's outputs and its runs' small files
SKIP_DIRS = {"checkpoints", "tb", "tensorboard"}
MAX_FILE = 2 << 20  # bytes: a larger file is not published


@dataclass(frozen=True)
class Entry:
    folder: str
    args: str  # the command after `farsighter`, without --out (split as a shell would)
    note: str
    earlier: int  # seconds it took when made by hand at an earlier commit (docs/results/README)


_REFIT_ZERO = "'Farsighter (no optimism in place, refit or zero targets, cut delay 3)'"
"""The agent of the refit-zero screens (session 40's default)."""
_ADVANTAGE = "'Farsighter (advantage learning 0.9)'"
"""The agent of the advantage-learning screens (session 41; the default's config since)."""
_REVISIT = {
    "uniform": (
        "'Farsighter (uniform at revisits)'",
        "uniform (a uniform action at every revisit)",
    ),
    "unpaid": (
        "'Farsighter (uniform at revisits after unpaid episodes)'",
        "uniform-unpaid (a uniform action at a revisit after an episode that paid nothing)",
    ),
    "timeout": (
        "'Farsighter (uniform at revisits after time limits)'",
        "uniform-timeout (a uniform action at a revisit after an episode that ran to its time "
        "limit)",
    ),
}
"""The agents of the revisit-action screens (session 42) and what each rule does."""
_SEEDS5 = "--seeds 1 2 3 4 5 "
_DK6_TASK = "MiniGrid DoorKey-6x6 (80k of its 250k steps)"
_DK6_UNIFORM = "--steps 80000 --workers 2 --seeds-per-batch 3"
_DK6_UNPAID = "--steps 80000 --workers 1 --seeds-per-batch 5"

ENTRIES = (
    Entry(
        "maze",
        "maze --agents all --workers 2",
        "9 agents x 5 seeds x 40k steps on the bridge maze (paper section 5.1); "
        "`farsighter maze --plot-only docs/results/maze` redraws it",
        972,
    ),
    Entry(
        "k-study",
        "k-study --workers 2",
        "Farsighter at k = 1, 10, 50, 150, 500 and adaptive k on the bridge maze, 5 seeds x 40k "
        "steps (Figure 4)",
        408,
    ),
    Entry(
        "explore",
        "explore --families chain --sizes 5 10 20 30 --agents DDQN k-DDQN BDQN Farsighter "
        "'Farsighter (redraw k)' 'Farsighter (redraw episode)' OB2I RND",
        "the chain family, 8 agents x 4 lengths x 5 seeds",
        802,
    ),
    Entry(
        "explore/chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents Farsighter",
        "chain of length 30, the defaults, 5 seeds",
        227,
    ),
    Entry(
        "explore/deepsea",
        "explore --families deepsea --sizes 6 8 10 12 --seeds 1 2 3 --agents DDQN Farsighter "
        "'Farsighter (redraw revisit)'",
        "bsuite's deep sea, N = 6 to 12, 3 seeds",
        1722,
    ),
    Entry(
        "explore/deepsea-large",
        "explore --families deepsea --sizes 14 17 20 --seeds 1 2 3 --agents Farsighter",
        "deep sea N = 14, 17, 20, Farsighter, 3 seeds",
        1505,
    ),
    Entry(
        "explore/deepsea-bsuite",
        "explore --families deepsea --sizes 10 14 20 --seeds 1 2 3 4 5 --agents Farsighter "
        "--episodes 10000 --workers 2",
        "deep sea for bsuite's run length (10,000 episodes), the defaults, 5 seeds (issue #25)",
        2700,
    ),
    Entry(
        "explore/deepsea-stochastic",
        "explore --families deepsea-stochastic --sizes 6 10 --seeds 1 2 3 --agents Farsighter "
        "'Farsighter (k-step target)'",
        "stochastic deep sea: k_target max against the plain k-step target",
        174,
    ),
    Entry(
        "explore/redraw-k-classic",
        "explore --families mountaincar acrobot --seeds 1 2 3 --steps 100000 "
        "--agents 'Farsighter (redraw k)'",
        "MountainCar and Acrobot, Farsighter's draw held for k steps (issue #25 item 3)",
        606,
    ),
    Entry(
        "explore/redraw-step-classic",
        "explore --families mountaincar acrobot --seeds 1 2 3 --steps 100000 "
        "--agents DDQN 'Farsighter (redraw step)'",
        "the same with a draw per step, Algorithm 2 (the default before), and DDQN",
        769,
    ),
    Entry(
        "explore/redraw-k-deepsea",
        "explore --families deepsea --sizes 10 14 --seeds 1 2 3 4 5 "
        "--agents 'Farsighter (redraw k)'",
        "deep sea N = 10 and 14 with the draw held for k steps; a draw per step: deepsea-bsuite",
        260,
    ),
    Entry(
        "explore/redraw-k-chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents 'Farsighter (redraw k)'",
        "the chain of length 30 with the draw held for k steps; a draw per step: chain30",
        124,
    ),
    Entry(
        "explore/targets",
        "explore --families chain frozenlake --sizes 4 30 --seeds 1 2 3 4 5 --agents Farsighter "
        "'Farsighter (k-step target)' 'Farsighter (mean target)' "
        "'Farsighter (mean, k-step target)' DDQN",
        "the next-state value (posterior draw or mean) x k_target (max or k) on the chain of "
        "length 30 and the slippery 4 x 4 FrozenLake",
        708,
    ),
    Entry(
        "explore/targets-deepsea",
        "explore --families deepsea deepsea-stochastic --sizes 10 14 --seeds 1 2 3 4 5 "
        "--agents Farsighter 'Farsighter (mean target)'",
        "the posterior-mean target against the default's posterior draw on deep sea and its "
        "stochastic version, N = 10 and 14",
        479,
    ),
    Entry(
        "explore/targets-doorkey",
        "explore --families doorkey --sizes 5 --seeds 1 2 3 --agents Farsighter "
        "'Farsighter (mean target)'",
        "the posterior-mean target against the posterior draw on MiniGrid DoorKey-5x5, 3 seeds "
        "x 100k steps",
        472,
    ),
    Entry(
        "explore/targets-classic",
        "explore --families mountaincar acrobot --seeds 1 2 3 --steps 100000 "
        "--agents Farsighter 'Farsighter (mean target)'",
        "the posterior-mean target against the posterior draw on MountainCar-v0 and Acrobot-v1, "
        "3 seeds x 100k steps",
        555,
    ),
    Entry(
        "explore/random-features",
        "explore --families deepsea --sizes 10 14 20 30 --seeds 1 2 3 4 5 "
        "--agents 'Farsighter (random features)'",
        "the posterior over learned and 512 fixed random features (the default since), on deep "
        "sea N = 10, 14, 20 and 30",
        0,
    ),
    Entry(
        "explore/random-features-tasks",
        "explore --families chain frozenlake --sizes 4 30 --seeds 1 2 3 4 5 "
        "--agents 'Farsighter (random features)'",
        "the same on the chain of length 30 and the slippery 4 x 4 FrozenLake",
        0,
    ),
    Entry(
        "explore/random-features-classic",
        "explore --families mountaincar acrobot --seeds 1 2 3 --steps 100000 "
        "--agents 'Farsighter (random features)'",
        "the same on MountainCar-v0 and Acrobot-v1, 3 seeds x 100k steps (over the learned "
        "features alone: targets-classic)",
        0,
    ),
    Entry(
        "explore/deepsea-17-24",
        "explore --families deepsea --sizes 17 24 --seeds 1 2 3 4 5 --agents Farsighter "
        "--workers 1",
        "the defaults on deep sea N = 17 and 24, between random-features' N = 20 and 30",
        0,
    ),
    Entry(
        "explore/centred-chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents 'Farsighter (centred "
        "draw)' --workers 1",
        "blr.center_sample (the sampled target's optimism centred per minibatch) on the chain",
        0,
    ),
    Entry(
        "explore/centred-frozenlake",
        "explore --families frozenlake --sizes 4 --seeds 1 2 3 4 5 --agents 'Farsighter "
        "(centred draw)' --workers 1",
        "the same on FrozenLake 4 x 4 (the raw draw: 0/5 in random-features-tasks)",
        0,
    ),
    Entry(
        "explore/centred-deepsea",
        "explore --families deepsea --sizes 10 14 20 --seeds 1 2 3 4 5 --agents 'Farsighter "
        "(centred draw)' --workers 2",
        "the same on deep sea N = 10, 14, 20 (the raw draw: 5/5, 5/5, 5/5 in random-features)",
        0,
    ),
    Entry(
        "explore/prior-deepsea24",
        "explore --families deepsea --sizes 24 --seeds 1 2 3 4 5 --agents 'Farsighter (prior 3)' "
        "'Farsighter (prior 10)' --workers 2",
        "a wider prior (blr.prior_std 3 and 10) on deep sea N = 24 (the defaults: 0/5 in "
        "deepsea-17-24)",
        0,
    ),
    Entry(
        "explore/prior10-chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents 'Farsighter (prior 10)' "
        "--workers 2",
        "the wider prior on the chain L = 30 (the defaults: 5/5 in random-features-tasks)",
        0,
    ),
    Entry(
        "explore/prior10-frozenlake",
        "explore --families frozenlake --sizes 4 --seeds 1 2 3 4 5 --agents 'Farsighter (prior "
        "10)' --workers 2",
        "the wider prior on FrozenLake 4 x 4 (the defaults: 0/5 in random-features-tasks)",
        0,
    ),
    Entry(
        "explore/prior10-classic",
        "explore --families mountaincar acrobot --seeds 1 2 3 --steps 100000 --agents "
        "'Farsighter (prior 10)' --workers 2",
        "the wider prior on MountainCar-v0 and Acrobot-v1 (the defaults: 3/3 and 3/3 in "
        "random-features-classic)",
        0,
    ),
    Entry(
        "explore/prior3-acrobot",
        "explore --families acrobot --seeds 1 2 3 --steps 100000 --agents 'Farsighter (prior 3)' "
        "--workers 2",
        "the prior 3 on Acrobot-v1, where the prior 10 failed (the defaults: 3/3 in "
        "random-features-classic; the prior 10: 0/3 in prior10-classic)",
        0,
    ),
    Entry(
        "explore/prior3-chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (prior 3)' --workers 2",
        "the prior 3 on the chain L = 30 (the defaults: 5/5 in random-features-tasks)",
        0,
    ),
    Entry(
        "explore/prior3-mountaincar",
        "explore --families mountaincar --seeds 1 2 3 --steps 100000 --agents "
        "'Farsighter (prior 3)' --workers 2",
        "the prior 3 on MountainCar-v0 (the defaults: 3/3 in random-features-classic)",
        0,
    ),
    Entry(
        "explore/prior3-deepsea",
        "explore --families deepsea --sizes 10 14 20 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (prior 3)' --workers 2",
        "the prior 3 on deep sea N = 10, 14 and 20 (the defaults: random-features)",
        0,
    ),
    Entry(
        "explore/prior3-frozenlake",
        "explore --families frozenlake --sizes 4 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (prior 3)' --workers 2",
        "the prior 3 on FrozenLake 4 x 4 (the defaults: 0/5 in random-features-tasks)",
        0,
    ),
    Entry(
        "explore/fourier-deepsea",
        "explore --families deepsea --sizes 24 30 --seeds 1 2 --agents "
        "'Farsighter (Fourier features)' --workers 2",
        "random Fourier features (blr.random_features_kind fourier) in place of the ReLU ones on "
        "deep sea N = 24 and 30, 2 seeds (the defaults: 0/5 at N = 24 in deepsea-17-24, 0/5 at "
        "N = 30 in random-features)",
        0,
    ),
    Entry(
        "explore/doorkey",
        "explore --families doorkey --sizes 5 --seeds 1 2 3 --agents DDQN Farsighter "
        "'Farsighter (redraw revisit)'",
        "MiniGrid DoorKey-5x5, 3 seeds x 100k steps",
        517,
    ),
    Entry(
        "explore/empty5",
        "explore --families empty --sizes 5 --seeds 1 2 3 --agents Farsighter DDQN "
        "'Farsighter (greedy-action draw)' --workers 2",
        "MiniGrid Empty-5x5, 3 seeds x 50k steps: the defaults' survival bonus against the goal "
        "that ends the episode (docs/design.md, the plainest MiniGrid room)",
        862,
    ),
    Entry(
        "explore/empty5-mean-kstep",
        "explore --families empty --sizes 5 --seeds 1 2 3 --agents "
        "'Farsighter (mean, k-step target)' --workers 2 --seeds-per-batch 1",
        "MiniGrid Empty-5x5 with neither upward bias (the mean target and the k-step target)",
        339,
    ),
    Entry(
        "explore/empty8",
        "explore --families empty --sizes 8 --seeds 1 --agents Farsighter "
        "'Farsighter (mean, k-step target)' --workers 2",
        "MiniGrid Empty-8x8, one seed x 100k steps: the defaults against the mean and k-step pair",
        403,
    ),
    Entry(
        "explore/doorkey5-mean-kstep",
        "explore --families doorkey --sizes 5 --seeds 1 2 3 --agents "
        "'Farsighter (mean, k-step target)' --workers 2 --seeds-per-batch 1",
        "MiniGrid DoorKey-5x5, 3 seeds x 100k steps, with neither upward bias (the defaults: 0/3)",
        706,
    ),
    Entry(
        "explore/until-reward",
        "explore --families chain deepsea empty doorkey --sizes 30 20 5 --seeds 1 2 3 4 5 "
        "--agents 'Farsighter (optimism until reward)' --workers 2",
        "blr.optimism until-reward on the chain L = 30, deep sea N = 20, Empty-5x5 and "
        "DoorKey-5x5 (made as four calls, one a task, the MiniGrid ones with 3 seeds; this "
        "one call also runs the chain at 5 and 20, deep sea at 30 and MiniGrid seeds 4 and 5)",
        1814,
    ),
    Entry(
        "explore/until-reward-cut",
        "explore --families chain deepsea empty frozenlake doorkey --sizes 30 20 5 4 --seeds 1 2 3 "
        "4 5 --agents 'Farsighter (optimism until reward, then cut)' --workers 2 "
        "--seeds-per-batch 1",
        "the default since session 32 (optimism until the first reward, then the mean's target "
        "cut before exploratory actions) on the chain L = 30, deep sea N = 20, Empty-5x5, "
        "FrozenLake 4x4 and DoorKey-5x5 (made as five calls, one a task, the MiniGrid ones with "
        "3 seeds; this one call also runs the other sizes the families share and MiniGrid "
        "seeds 4 and 5)",
        1667,
    ),
    Entry(
        "explore/switch-deepsea",
        "explore --families deepsea --sizes 10 14 --seeds 1 2 3 4 5 --agents Farsighter "
        "--workers 2",
        "the defaults since session 32 on deep sea N = 10 and 14 (their seeds in batches)",
        362,
    ),
    Entry(
        "explore/switch-deepsea-stochastic",
        "explore --families deepsea-stochastic --sizes 6 10 14 --seeds 1 2 3 4 5 --agents "
        "Farsighter --workers 2",
        "the defaults since session 32 on the stochastic deep sea N = 6, 10 and 14",
        303,
    ),
    Entry(
        "explore/switch-empty8",
        "explore --families empty --sizes 8 --seeds 1 2 --agents Farsighter --workers 2",
        "the defaults since session 32 on MiniGrid Empty-8x8, 2 seeds x 100k steps",
        300,
    ),
    Entry(
        "explore/until-reward-empty8",
        "explore --families empty --sizes 8 --seeds 1 2 --agents "
        "'Farsighter (optimism until reward)' --workers 2",
        "the switch with the plain k-step target after it on MiniGrid Empty-8x8, 2 seeds",
        268,
    ),
    Entry(
        "explore/cut-margin",
        "explore --families chain empty --sizes 30 8 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (cut margin 1)' --workers 2",
        "blr.cut_margin 1 on the chain L = 30 (5 seeds) and Empty-8x8 (made as two calls, "
        "Empty-8x8 with seeds 1 and 2; this one call also runs the chain at 8 and Empty at 30 "
        "where the families have them, and Empty seeds 3 to 5)",
        371,
    ),
    Entry(
        "explore/cut-chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents 'Farsighter (cut)' "
        "'Farsighter (cut, optimism until reward)' --workers 2",
        "the k-step target cut before exploratory actions with the draw for the whole run, and "
        "from the start with the switch, on the chain L = 30",
        255,
    ),
    Entry(
        "explore/restart-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 2 3 --agents "
        "'Farsighter (switch restart)' --workers 2 --seeds-per-batch 1",
        "the posterior restarted at the switch, then the cut target, on DoorKey-5x5 (the two "
        "seeds that switch)",
        459,
    ),
    Entry(
        "explore/restart-margin-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 2 3 --agents "
        "'Farsighter (switch restart, cut margin 1)' --workers 2 --seeds-per-batch 1",
        "the restart with the cut at margin 1 on DoorKey-5x5 (the two seeds that switch)",
        445,
    ),
    Entry(
        "explore/restart-chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (switch restart)' 'Farsighter (switch restart, k-step)' --workers 2",
        "the restart with the cut and with the plain k-step target after it, chain L = 30",
        235,
    ),
    Entry(
        "explore/restart-margin-chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (switch restart, cut margin 1)' --workers 2",
        "the restart with the cut at margin 1, chain L = 30",
        176,
    ),
    Entry(
        "explore/zero-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 2 3 --agents 'Farsighter (zero targets)' "
        "'Farsighter (zero targets, cut margin 1)' --workers 2 --seeds-per-batch 1",
        "the optimistic targets zeroed at the switch (the rows kept), with the cut at margin 0 "
        "and 1, on DoorKey-5x5 (the two seeds that switch)",
        898,
    ),
    Entry(
        "explore/zero-chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (zero targets)' 'Farsighter (zero targets, cut margin 1)' --workers 2",
        "the optimistic targets zeroed at the switch, cut at margin 0 and 1, chain L = 30",
        265,
    ),
    Entry(
        "explore/delay-chain30",
        "explore --families chain --sizes 30 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (zero targets, cut delay 3)' --workers 2",
        "the targets zeroed at the switch, then the cut only past 3 steps of delay, chain L = 30",
        157,
    ),
    Entry(
        "explore/delay-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 2 3 --agents "
        "'Farsighter (zero targets, cut delay 3)' --workers 2 --seeds-per-batch 1",
        "the targets zeroed at the switch, then the cut only past 3 steps of delay, DoorKey-5x5 "
        "(the two seeds that switch)",
        400,
    ),
    Entry(
        "explore/delay-deepsea20",
        "explore --families deepsea --sizes 20 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (zero targets, cut delay 3)' --workers 2",
        "the targets zeroed at the switch and the cut past 3 steps of delay, deep sea N = 20",
        400,
    ),
    Entry(
        "explore/delay-frozenlake",
        "explore --families frozenlake --sizes 4 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (zero targets, cut delay 3)' --workers 2",
        "the same on FrozenLake 4x4",
        326,
    ),
    Entry(
        "explore/delay-empty5",
        "explore --families empty --sizes 5 --seeds 1 2 3 --agents "
        "'Farsighter (zero targets, cut delay 3)' --workers 2",
        "the same on MiniGrid Empty-5x5",
        366,
    ),
    Entry(
        "explore/delay-only-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 2 3 --agents "
        "'Farsighter (cut delay 3)' --workers 2 --seeds-per-batch 1",
        "the cut only past 3 steps of delay, the optimistic targets kept at the switch, "
        "DoorKey-5x5 (the two seeds that switch)",
        389,
    ),
    Entry(
        "explore/rearm-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 2 3 --agents 'Farsighter (rearm 10)' "
        "'Farsighter (rearm 10, cut delay 3)' --workers 2 --seeds-per-batch 1",
        "the optimism taken up again after 10 unpaid episodes since the switch, with the "
        "default cut and with the cut past 3 steps of delay, DoorKey-5x5",
        1443,
    ),
    Entry(
        "explore/inplace-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 1 2 3 --agents "
        "'Farsighter (no optimism in place)' --workers 2 --seeds-per-batch 1",
        "no draw in a target whose window ends where it began (blr.stay_optimism False), "
        "DoorKey-5x5",
        771,
    ),
    Entry(
        "explore/inplace-revisit-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 1 2 3 --agents "
        "'Farsighter (no optimism in place, redraw revisit)' --workers 2 --seeds-per-batch 1",
        "the same with the draw redrawn where the episode returns to an observation, DoorKey-5x5",
        1358,
    ),
    Entry(
        "explore/inplace-zero-delay-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 1 2 3 --agents "
        "'Farsighter (no optimism in place, zero targets, cut delay 3)' --workers 2 "
        "--seeds-per-batch 1",
        "no optimism for staying put, the targets zeroed at the switch, the cut past 3 steps of "
        "delay, DoorKey-5x5",
        746,
    ),
    Entry(
        "explore/inplace-zero-delay-frozenlake",
        "explore --families frozenlake --sizes 4 --seeds 1 2 3 4 5 --agents "
        "'Farsighter (no optimism in place, zero targets, cut delay 3)' --workers 2",
        "the same on FrozenLake 4x4",
        315,
    ),
    Entry(
        "explore/inplace-zero-delay-empty5",
        "explore --families empty --sizes 5 --seeds 1 2 3 --agents "
        "'Farsighter (no optimism in place, zero targets, cut delay 3)' --workers 2",
        "the same on MiniGrid Empty-5x5",
        355,
    ),
    Entry(
        "explore/inplace-zero-delay-doorkey5-s45",
        "explore --families doorkey --sizes 5 --seeds 4 5 --agents "
        "'Farsighter (no optimism in place, zero targets, cut delay 3)' --workers 2 "
        "--seeds-per-batch 1",
        "the same on DoorKey-5x5, seeds 4 and 5",
        398,
    ),
    Entry(
        "explore/driftchain",
        "explore --families driftchain --sizes 6 10 --agents DDQN Farsighter "
        "'Farsighter (optimism until reward, then cut)' --workers 2",
        "the drifting lock (a wrong move one state back): the defaults, the targets kept at the "
        "switch (the defaults up to session 36) and DDQN",
        144,
    ),
    Entry(
        "explore/restart-deepsea",
        "explore --families deepsea --sizes 10 14 --agents 'Farsighter (switch restart)' "
        "--workers 2",
        "the posterior restarted at the switch (the default since session 37), deep sea N = 10, 14",
        362,
    ),
    Entry(
        "explore/restart-deepsea20",
        "explore --families deepsea --sizes 20 --agents 'Farsighter (switch restart)' --workers 2",
        "the same, deep sea N = 20",
        390,
    ),
    Entry(
        "explore/zero-deepsea20",
        "explore --families deepsea --sizes 20 --agents 'Farsighter (zero targets)' --workers 2",
        "the targets zeroed at the switch instead, deep sea N = 20",
        374,
    ),
    Entry(
        "explore/restart-chain30-s37",
        "explore --families chain --sizes 30 --agents 'Farsighter (switch restart)' --workers 2",
        "the posterior restarted at the switch, the chain L = 30 (with the act_width default)",
        136,
    ),
    Entry(
        "explore/restart-frozenlake",
        "explore --families frozenlake --sizes 4 --agents 'Farsighter (switch restart)' "
        "--workers 2",
        "the posterior restarted at the switch, FrozenLake 4 x 4",
        512,
    ),
    Entry(
        "explore/restart-empty5",
        "explore --families empty --sizes 5 --agents 'Farsighter (switch restart)' --workers 2",
        "the posterior restarted at the switch, MiniGrid Empty-5x5",
        673,
    ),
    Entry(
        "explore/refit-deepsea-driftchain",
        "explore --families driftchain deepsea --sizes 10 14 20 --agents "
        "'Farsighter (refit at switch)' --workers 2",
        "the posterior refitted to the replay at the switch (session 38, not the default), "
        "the drifting lock and deep sea at 10, 14 and 20",
        956,
    ),
    Entry(
        "explore/refit-tasks",
        "explore --families chain frozenlake deepsea-stochastic --sizes 30 4 10 --agents "
        "'Farsighter (refit at switch)' --workers 2",
        "the same, the chain L = 10 and 30, FrozenLake 4 x 4 and stochastic deep sea N = 10",
        460,
    ),
    Entry(
        "explore/refit-early",
        "explore --families empty frozenlake deepsea --sizes 5 4 10 --agents "
        "'Farsighter (refit at switch)' --workers 2",
        "the same where the first reward can come before the first update (which then restarts "
        "from the prior alone): MiniGrid Empty-5x5, FrozenLake 4 x 4, deep sea N = 10",
        1031,
    ),
    Entry(
        "explore/guard-deepsea-driftchain",
        "explore --families driftchain deepsea --sizes 10 14 20 --agents "
        "'Farsighter (refit at switch)' --workers 2",
        "the refit with its check (a fit whose targets pass the largest reward sum the replay "
        "showed is dropped; session 39, the default since): the drifting lock and deep sea at "
        "10, 14 and 20",
        974,
    ),
    Entry(
        "explore/guard-tasks",
        "explore --families chain frozenlake deepsea-stochastic empty --sizes 30 4 10 5 "
        "--agents 'Farsighter (refit at switch)' --workers 2",
        "the same, the chain L = 5, 10 and 30, FrozenLake 4 x 4, stochastic deep sea N = 10 and "
        "MiniGrid Empty-5x5",
        854,
    ),
    Entry(
        "explore/deepsea-growth-s39",
        "explore --families deepsea --agents Farsighter --workers 2",
        "deep sea at every size, N = 6 to 30, with the defaults of session 39 (the posterior "
        "refitted at the switch), 5 seeds: the growth of the episodes to solve (issue #25 "
        "item 4)",
        3065,
    ),
    Entry(
        "explore/deepsea30-s40",
        "explore --families deepsea --sizes 30 --seeds 1 2 3 --agents Farsighter --workers 1 "
        "--episodes 6000",
        "deep sea N = 30 with the defaults of session 39, the three seeds that 3,000 episodes "
        "censored in explore/deepsea-growth-s39, given 6,000 (their first 3,000 episodes are "
        "those runs')",
        2846,
    ),
    Entry(
        "explore/doorkey5-s40",
        "explore --families doorkey --sizes 5 --seeds 1 2 3 4 5 --agents Farsighter --workers 2",
        "MiniGrid DoorKey-5x5 with the defaults of session 39 (the posterior refitted at the "
        "switch), 5 seeds, 100k steps",
        1210,
    ),
    Entry(
        "explore/refit-zero-deepsea20",
        f"explore --families deepsea --sizes 20 --agents {_REFIT_ZERO} --workers 1",
        "deep sea N = 20 with the refit at the switch, zeroed targets where the fit is rejected, "
        "no optimism in place and the cut past 3 steps of delay, 5 seeds",
        618,
    ),
    *(
        Entry(
            f"explore/refit-zero-{name}",
            f"explore --families {family} --sizes {sizes} --agents {_REFIT_ZERO} --workers 1",
            f"the same agent on {tasks}, 5 seeds",
            seconds,
        )
        for name, family, sizes, tasks, seconds in (
            ("doorkey5", "doorkey", "5", "MiniGrid DoorKey-5x5 (100k steps)", 1505),
            ("deepsea1014", "deepsea", "10 14", "deep sea N = 10 and 14", 410),
            ("driftchain", "driftchain", "10 14 20", "the drifting lock L = 10, 14 and 20", 770),
            ("chain", "chain", "5 10 30", "the chain L = 5, 10 and 30", 328),
            ("frozenlake", "frozenlake", "4", "FrozenLake 4 x 4", 448),
            ("empty", "empty", "5", "MiniGrid Empty-5x5", 987),
            ("deepsea-stochastic", "deepsea-stochastic", "10", "stochastic deep sea N = 10", 88),
        )
    ),
    Entry(
        "explore/advantage-doorkey5",
        "explore --families doorkey --sizes 5 --seeds 1 2 3 4 5 --agents Farsighter --workers 2 "
        "--seeds-per-batch 1",
        "MiniGrid DoorKey-5x5 with advantage learning after the switch (blr.advantage_learning "
        "0.9, the default since), 5 seeds, 100k steps; run from a patch of the loss with the "
        "option's arithmetic, before the field existed (its runs' config.json lack it; seed 1's "
        "first 20k steps equal the option's run, episode for episode)",
        1295,
    ),
    *(
        Entry(
            f"explore/advantage-{name}",
            f"explore --families {family} --sizes {sizes} --agents {_ADVANTAGE} --workers "
            f"{workers}",
            f"the same on {tasks}, 5 seeds",
            seconds,
        )
        for name, family, sizes, workers, tasks, seconds in (
            ("deepsea", "deepsea", "10 14 20", 2, "deep sea N = 10, 14 and 20", 722),
            ("chain", "chain", "5 10 30", 2, "the chain L = 5, 10 and 30", 211),
            ("driftchain", "driftchain", "10 14 20", 2, "the drifting lock L = 10, 14, 20", 432),
            ("frozenlake", "frozenlake", "4", 1, "FrozenLake 4 x 4", 639),
            ("empty", "empty", "5", 1, "MiniGrid Empty-5x5", 924),
            (
                "deepsea-stochastic",
                "deepsea-stochastic",
                "10",
                1,
                "stochastic deep sea N = 10",
                117,
            ),
        )
    ),
    *(
        Entry(
            f"explore/revisit-{rule}-{name}",
            f"explore --families {family} --sizes {size} {seeds}--agents {_REVISIT[rule][0]} "
            f"{extra}",
            f"blr.revisit_action {_REVISIT[rule][1]} on {task}, 5 seeds",
            seconds,
        )
        for rule, name, family, size, seeds, extra, task, seconds in (
            ("uniform", "doorkey6", "doorkey", 6, _SEEDS5, _DK6_UNIFORM, _DK6_TASK, 874),
            ("unpaid", "doorkey6", "doorkey", 6, _SEEDS5, _DK6_UNPAID, _DK6_TASK, 1268),
            ("uniform", "empty", "empty", 5, "", "--workers 1", "MiniGrid Empty-5x5", 743),
            ("unpaid", "empty", "empty", 5, "", "--workers 1", "MiniGrid Empty-5x5", 732),
            ("uniform", "frozenlake", "frozenlake", 4, "", "--workers 1", "FrozenLake 4 x 4", 508),
            ("unpaid", "frozenlake", "frozenlake", 4, "", "--workers 1", "FrozenLake 4 x 4", 474),
            ("timeout", "frozenlake", "frozenlake", 4, "", "--workers 1", "FrozenLake 4 x 4", 460),
            (
                "timeout",
                "doorkey5",
                "doorkey",
                5,
                _SEEDS5,
                "--workers 2 --seeds-per-batch 1",
                "MiniGrid DoorKey-5x5 (100k steps)",
                1104,
            ),
            (
                "unpaid",
                "driftchain",
                "driftchain",
                "10 14 20",
                "",
                "--workers 1",
                "the drifting lock L = 10, 14 and 20",
                867,
            ),
        )
    ),
    Entry(
        "explore/doorkey8-s43",
        "explore --families doorkey --sizes 8 --agents Farsighter --seeds 1 2 3 4 5 --steps 500000 "
        "--workers 2 --seeds-per-batch 1",
        "the default on MiniGrid DoorKey-8x8, 500k of its 1M steps, 5 seeds",
        5418,
    ),
    Entry(
        "explore/keycorridor1-s43",
        "explore --families keycorridor --sizes 1 --agents DDQN Farsighter --seeds 1 2 3 "
        "--workers 1 --seeds-per-batch 1",
        "DDQN and the default on MiniGrid KeyCorridorS3R1 (100k steps), 3 seeds",
        1258,
    ),
    Entry(
        "explore/multiroom2-s43",
        "explore --families multiroom --sizes 2 --agents DDQN Farsighter --seeds 1 2 3 "
        "--workers 1 --seeds-per-batch 1",
        "DDQN and the default on MiniGrid MultiRoom-N2-S4 (100k steps), 3 seeds",
        1297,
    ),
    Entry(
        "explore/deepsea-growth-ddqn-s43",
        "explore --families deepsea --agents DDQN --seeds 1 2 3 4 5 --workers 2 --seeds-per-batch 3",
        "DDQN on deep sea at every size, N = 6 to 30, 5 seeds: its growth (issue #25 item 4)",
        676,
    ),
    Entry(
        "explore/deepsea-growth-s44",
        "explore --families deepsea --agents DDQN Farsighter --seeds 1 2 3 4 5 --workers 2",
        "deep sea at every size, N = 6 to 30, DDQN and the defaults in one study, 5 seeds: "
        "both growths and the claim between them (issue #25 item 4; DDQN's runs are those of "
        "explore/deepsea-growth-ddqn-s43, copied in and kept as finished, 676 s of the time)",
        3380,
    ),
    Entry(
        "explore/chain30-s44",
        "explore --families chain --sizes 30 --agents Farsighter --seeds 1 2 3 4 5 --workers 2",
        "the chain L = 30 with the defaults of session 42, 5 seeds (issue #25's goal: still 5 "
        "of 5)",
        145,
    ),
    Entry(
        "minatar",
        "atari --games minatar --agents DDQN BDQN Farsighter --seeds 1 2 --steps 50000 "
        "--eval-every 10000 --eval-episodes 10",
        "3 agents x 5 MinAtar games x 2 seeds x 50k steps",
        3415,
    ),
    Entry(
        "atari100k",
        "atari --games Boxing Freeway --agents Farsighter --seeds 1 --steps 100000 "
        "--preset atari100k --eval-every 25000 --eval-episodes 5",
        "Atari-100k, 2 games, 1 seed",
        2796,
    ),
    Entry(
        "walker2d",
        "robotics --env Walker2d-v5 --steps 30000 --seeds 1 2 3 --workers 2",
        "the four continuous agents on Walker2d-v5 at a small budget",
        583,
    ),
    Entry(
        "fetchpickandplace",
        "robotics --env FetchPickAndPlace-v4 --seeds 1 2 --steps 15000 --eval-every 1500 "
        "--eval-episodes 10",
        "goal task with HER, a tiny fraction of the paper's budget",
        253,
    ),
    Entry(
        "handmanipulateblock",
        "robotics --env HandManipulateBlock-v1 --seeds 1 2 --steps 5000 --eval-every 1000 "
        "--eval-episodes 5",
        "goal task with HER, a tiny fraction of the paper's budget",
        122,
    ),
)


def publish(build: Path, dest: Path) -> None:
    """Replace ``dest`` with ``build``'s outputs and its runs' small files."""
    prefix = dest.relative_to(RESULTS).as_posix() + "/"
    # a study folder inside this one is its own entry
    kept = {RESULTS / e.folder for e in ENTRIES if e.folder.startswith(prefix)}
    if dest.exists():
        for item in dest.iterdir():
            if item not in kept:
                shutil.rmtree(item) if item.is_dir() else item.unlink()
    for file in sorted(build.rglob("*")):
        rel = file.relative_to(build)
        if not file.is_file() or SKIP_DIRS & set(rel.parts) or file.suffix not in KEEP:
            continue
        if file.stat().st_size > MAX_FILE:
            continue
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        if file.suffix in (".md", ".json", ".csv"):  # paths as where the files now live
            text = file.read_text().replace(str(build), dest.relative_to(ROOT).as_posix())
            (dest / rel).write_text(text)
        else:
            shutil.copy2(file, dest / rel)


def readme_table(times: dict[str, float]) -> str:
    rows = ["| folder | command | wall time |", "|---|---|---|"]
    for e in ENTRIES:
        command = f"farsighter {e.args}"
        took = (
            f"{times[e.folder]:.0f} s"
            if e.folder in times
            else f"not rerun yet ({e.earlier} s at the commit that added it)"
        )
        rows.append(f"| `{e.folder}/` | `{command}` ({e.note}) | {took} |")
    return "\n".join(rows)


def write_readme(times: dict[str, float]) -> None:
    readme = RESULTS / "README.md"
    text = readme.read_text()
    start, end = "<!-- results table -->", "<!-- end of the results table -->"
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    readme.write_text(f"{head}{start}\n{readme_table(times)}\n{end}{tail}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=None, help="folders (default: all)")
    parser.add_argument("--list", action="store_true", help="print the studies and stop")
    args = parser.parse_args()
    times = json.loads(TIMES.read_text()) if TIMES.exists() else {}
    folders = [e.folder for e in ENTRIES]
    unknown = sorted(set(args.only or ()) - set(folders))
    if unknown:
        print(f"unknown folder(s) {', '.join(unknown)}; accepted: {', '.join(folders)}")
        return 2
    if args.list:
        print(readme_table(times))
        return 0
    for e in ENTRIES:
        if args.only is not None and e.folder not in args.only:
            continue
        build = BUILD / e.folder
        cmd = [sys.executable, "-m", "farsighter", *shlex.split(e.args), "--out", str(build)]
        print(f"$ farsighter {e.args} --out {build}", flush=True)
        spent = build / "wall_seconds.txt"  # over every call that ran part of it
        before = float(spent.read_text()) if spent.exists() else 0.0
        start = time.perf_counter()
        subprocess.run(cmd, check=True, cwd=ROOT)
        times[e.folder] = round(before + time.perf_counter() - start, 1)
        spent.write_text(f"{times[e.folder]}\n")
        publish(build, RESULTS / e.folder)
        TIMES.write_text(json.dumps(times, indent=2) + "\n")
        write_readme(times)
    return 0


if __name__ == "__main__":
    sys.exit(main())
