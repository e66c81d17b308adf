"""Validation of a built config: every check gives one line saying what was wrong and what is
accepted (the CLI prints it and exits 2). Each section's dataclass checks its own fields beside
them (``checks`` in farsighter.config.fields); what is checked here depends on the algorithm or
spans sections."""

from __future__ import annotations

import math

from farsighter import algorithms
from farsighter.config.field_types import OPEN_CHOICES, field_value, leaf_fields
from farsighter.config.fields import Config, env_kwargs_dict
from farsighter.config.presets import flat_fields, is_atari_id
from farsighter.errors import ConfigError


def validate(cfg: Config) -> None:
    """Raise :class:`ConfigError` with one line naming the first problem and what is accepted."""
    _check_types(cfg)
    spec = algorithms.get(cfg.algo)
    sections = (cfg, cfg.runtime, cfg.atari, cfg.blr, cfg.adaptive_k, cfg.ob2i, cfg.rnd, cfg.naf)
    for checks in (*(s.checks() for s in sections), _algorithm_checks(cfg, spec)):
        for ok, message in checks:
            if not ok:
                raise ConfigError(message)
    _check_types(cfg, choices=True)  # named choices no section's check above names
    for name, value in flat_fields(cfg):  # config.json is strict JSON: no NaN or Infinity
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"{name} must be a finite number (got {value})")


ALE_SET = {
    "frameskip": "atari.frame_skip",
    "repeat_action_probability": "atari.repeat_action_probability",
    "max_num_frames_per_episode": "atari.max_frames_per_episode",
}
"""An ALE game's keywords of gymnasium.make that the atari section sets."""


def _check_types(cfg: Config, choices: bool = False) -> None:
    """Every field holds a value of its type (a config built with ``dataclasses.replace`` or by
    hand is checked as ``make_config`` checks keywords), before a check compares it; with
    ``choices``, a field of named choices one of them (but a registry's, ``OPEN_CHOICES``)."""
    for name, cls in leaf_fields()[1].items():
        if not isinstance(getattr(cfg, name), cls):
            got = getattr(cfg, name)
            raise ConfigError(f"{name} must be a {cls.__name__} (got {got!r})")
    for name, value in flat_fields(cfg):
        named = choices and name not in OPEN_CHOICES
        want = field_value(name, value, convert=False, choices=named)[1]
        if want:
            raise ConfigError(f"{name} must be {want} (got {value!r})")


def _algorithm_checks(cfg: Config, spec: algorithms.Algorithm) -> list[tuple[bool, str]]:
    """What the algorithm table allows, and the values that span sections."""
    adaptive = " and ".join(a.name for a in algorithms.TABLE if a.adaptive_k)
    step_algos = ", ".join(a.name for a in algorithms.TABLE if a.fast_step)
    ak, n = cfg.adaptive_k, cfg.naf
    return [
        (
            not ak.enabled or ak.k_min <= cfg.k <= ak.k_max,
            f"with adaptive k, the initial k ({cfg.k}) must lie in [k_min, k_max] = "
            f"[{ak.k_min}, {ak.k_max}]",
        ),
        (
            not spec.episodic or (cfg.k == 1 and not cfg.stride and not cfg.sample_recent),
            f"{cfg.algo} learns from whole episodes (episodic backward update): k must be 1 and "
            "stride and sample_recent off",
        ),
        (
            not ak.enabled or spec.adaptive_k,
            f"adaptive_k.enabled is only supported by --algo {adaptive}",
        ),
        (
            cfg.runtime.cuda_graph != "on" or spec.fast_step,
            f"cuda_graph on is supported by --algo {step_algos}; use auto or off",
        ),
        (
            not cfg.runtime.compile or spec.fast_step,
            f"compile is supported by --algo {step_algos}",
        ),
        (
            cfg.runtime.cuda_graph != "on" or not cfg.blr.switches_update,
            "cuda_graph on does not combine with blr.optimism until-reward (the general "
            "preset's: its switch changes the update mid-run); use cuda_graph auto or off "
            "(--compile compiles such a run), or --blr.optimism always",
        ),
        (
            cfg.k_target == "k" or spec.agent == "farsighter",
            "k_target max, max-mean and cut are only supported by --algo "
            + " and ".join(a.name for a in algorithms.TABLE if a.agent == "farsighter"),
        ),
        (
            not n.her or spec.actions == "continuous",
            "naf.her needs a continuous agent: "
            + algorithms.accepted(algorithms.names_for("continuous")),
        ),
        (
            spec.actions != "continuous" or n.elbo_batch <= cfg.buffer_size,
            f"naf.elbo_batch ({n.elbo_batch}) must not exceed buffer_size ({cfg.buffer_size})",
        ),
        (
            not (cfg.max_episode_steps and is_atari_id(cfg.env)),
            "max_episode_steps is for non-ALE ids; an ALE game's episodes are capped by "
            "atari.max_frames_per_episode (in frames)",
        ),
        (
            not (is_atari_id(cfg.env) and set(env_kwargs_dict(cfg.env_kwargs)) & set(ALE_SET)),
            f"env_kwargs cannot set an ALE game's {', '.join(ALE_SET)}: "
            f"{', '.join(ALE_SET.values())} set them",
        ),
        (
            not (cfg.env_kwargs and cfg.atari.backend == "envpool"),
            "env_kwargs go to gymnasium.make, and atari.backend envpool makes its games itself; "
            "use atari.backend gymnasium (or auto, which takes it when env_kwargs are given)",
        ),
    ]
