"""What ``policy.pt`` holds: what acting needs and no more (:func:`policy_state`), and how an
agent built from the run's config takes it back (:func:`load_policy_state`).

The checkpoint (``checkpoint.pt``) keeps everything that continues training: optimizer state,
target networks, the replay, a Bayesian head's float64 sufficient statistics. The policy file
keeps the networks that act:

* DQN-family agents (ddqn, kddqn): the online Q-network;
* agents with a BLR head (farsighter, bdqn): the torso and, per action, the posterior mean and
  the square-root factor U_a that the Thompson draws w_a = mean_a + U_a z use, in float32 (the
  precision they act in);
* the others (ob2i, rnd, krnd, the NAF family): their checkpoint state without optimizer state
  and target networks.

A policy file from before this format (the agent's whole state) loads as it did.
"""

from __future__ import annotations

from typing import Any

import torch

from farsighter import algorithms
from farsighter.agents import Agent
from farsighter.errors import RunDirError

POLICY_FORMAT = "farsighter-policy"
POLICY_VERSION = 1

ACTING: dict[str, tuple[str, ...]] = {"ddqn": ("q",), "farsighter": ("torso", "head")}
"""Agent module -> the entries of its state that acting reads (modules not listed here keep
their whole state but for optimizers and target networks)."""
HEAD_TENSORS = ("mean_AD", "sqrt_cov_ADD")
"""The tensors of a BLR head's state that acting reads (its other tensors are statistics)."""
TARGET_OF = {"q_target": "q", "torso_target": "torso", "net_target": "net"}
"""Target network -> its online network, whose weights a loaded policy gives it."""


def policy_state(agent: Agent, algo: str) -> dict[str, Any]:
    """What ``policy.pt`` saves of ``agent`` (an agent of ``algo``, or one seed of a batch: its
    state has the same entries)."""
    full = agent.state_dict(include_replay=False)
    keys = ACTING.get(algorithms.get(algo).agent)
    if keys is None:
        acting = {
            key: value
            for key, value in full.items()
            if key not in TARGET_OF and key != "replay" and not _is_optimizer(value)
        }
    else:
        acting = {key: full[key] for key in keys}
    if "head" in acting and keys is not None:
        head = acting["head"]
        acting["head"] = {
            key: value.float() if key in HEAD_TENSORS else value
            for key, value in head.items()
            if key in HEAD_TENSORS or not isinstance(value, torch.Tensor)
        }
    return {
        "format": POLICY_FORMAT,
        "version": POLICY_VERSION,
        "algo": algo,
        "agent": _compact(acting),
    }


def load_policy_state(agent: Agent, state: dict[str, Any]) -> None:
    """Load what :func:`policy_state` saved into ``agent`` (built from the run's config): the
    entries it left out stay as built (a BLR head's statistics zero, counters and generators
    fresh), and each target network takes its online network's weights."""
    if state.get("format") != POLICY_FORMAT:  # written before this format: the whole state
        agent.load_state_dict(state)
        return
    if int(state.get("version", 0)) > POLICY_VERSION:
        raise RunDirError(
            f"policy file format {state.get('version')} is newer than this version reads "
            f"({POLICY_VERSION}); load it with the farsighter version that wrote it"
        )
    acting: dict[str, Any] = state["agent"]
    merged = agent.state_dict(include_replay=False)
    for key, value in acting.items():
        merged[key] = {**merged[key], **value} if key == "head" else value
    for target, online in TARGET_OF.items():
        if target in merged and target not in acting and online in acting:
            merged[target] = acting[online]
    if "target_mean_AD" in merged and "target_mean_AD" not in acting and "head" in acting:
        merged["target_mean_AD"] = acting["head"]["mean_AD"]
    agent.load_state_dict(merged)


def _is_optimizer(value: Any) -> bool:
    """An optimizer's ``state_dict`` (its moments: training state, not acting)."""
    return isinstance(value, dict) and {"state", "param_groups"} <= value.keys()


def _compact(value: Any) -> Any:
    """``value`` with every tensor copied to its own storage on the CPU (a view of a larger
    tensor, such as one seed's slice of a batch's stacked weights, would save all of it)."""
    if isinstance(value, torch.Tensor):
        return value.detach().to("cpu", copy=True).contiguous()
    if isinstance(value, dict):
        return {key: _compact(item) for key, item in value.items()}
    if type(value) in (list, tuple):
        return type(value)(_compact(item) for item in value)
    return value
