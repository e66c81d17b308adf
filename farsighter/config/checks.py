"""Validation of a built config: every check gives one line saying what was wrong and what is
accepted (the CLI prints it and exits 2)."""

from __future__ import annotations

from farsighter import algorithms
from farsighter.config.fields import Config
from farsighter.errors import ConfigError


def validate(cfg: Config) -> None:
    """Raise :class:`ConfigError` with one line naming the first problem and what is accepted."""
    spec = algorithms.get(cfg.algo)
    for part in (_run_checks, _ob2i_rnd_checks, _algorithm_checks, _naf_checks):
        for ok, message in part(cfg, spec):
            if not ok:
                raise ConfigError(message)


def _run_checks(cfg: Config, spec: algorithms.Algorithm) -> list[tuple[bool, str]]:
    """The run, learning and BLR fields."""
    return [
        (cfg.k >= 1, f"k must be an integer >= 1 (got {cfg.k})"),
        (cfg.lr > 0, f"lr must be > 0 (got {cfg.lr})"),
        (cfg.buffer_size > 0, f"buffer_size must be > 0 (got {cfg.buffer_size})"),
        (cfg.batch_size > 0, f"batch_size must be > 0 (got {cfg.batch_size})"),
        (
            cfg.batch_size <= cfg.buffer_size,
            f"batch_size ({cfg.batch_size}) must not exceed buffer_size ({cfg.buffer_size})",
        ),
        (cfg.total_steps > 0, f"total_steps must be > 0 (got {cfg.total_steps})"),
        (cfg.num_envs >= 1, f"num_envs must be >= 1 (got {cfg.num_envs})"),
        (0.0 <= cfg.gamma <= 1.0, f"gamma must be in [0, 1] (got {cfg.gamma})"),
        (cfg.train_every >= 1, f"train_every must be >= 1 (got {cfg.train_every})"),
        (
            cfg.target_update_every >= 1,
            f"target_update_every must be >= 1 (got {cfg.target_update_every})",
        ),
        (cfg.learning_starts >= 0, f"learning_starts must be >= 0 (got {cfg.learning_starts})"),
        (
            0.0 <= cfg.eps_end <= 1.0 and 0.0 <= cfg.eps_start <= 1.0,
            "eps_start and eps_end must be in [0, 1]",
        ),
        (0.0 <= cfg.eval_epsilon <= 1.0, "eval_epsilon must be in [0, 1]"),
        (cfg.eps_decay_steps >= 0, "eps_decay_steps must be >= 0"),
        (cfg.recent_window >= 0, "recent_window must be >= 0 (0 means target_update_every)"),
        (
            cfg.effective_recent_window <= cfg.buffer_size,
            f"recent window ({cfg.effective_recent_window}) must not exceed buffer_size "
            f"({cfg.buffer_size})",
        ),
        (  # max(.., 1): the list is built whole, so a bad num_envs must not divide by zero here
            cfg.k <= cfg.buffer_size // max(cfg.num_envs, 1),
            f"k ({cfg.k}) must not exceed the per-environment buffer "
            f"({cfg.buffer_size // max(cfg.num_envs, 1)})",
        ),
        (all(h > 0 for h in cfg.hidden_sizes), "hidden_sizes must be positive integers"),
        (cfg.eval_episodes >= 1, "eval_episodes must be >= 1"),
        (
            cfg.eval_every >= 0,
            f"eval_every must be >= 0 (0: no periodic evaluation; got {cfg.eval_every})",
        ),
        (cfg.eval_max_steps >= 1, f"eval_max_steps must be >= 1 (got {cfg.eval_max_steps})"),
        (cfg.log_every >= 1, f"log_every must be >= 1 (got {cfg.log_every})"),
        (cfg.checkpoint_every >= 0, "checkpoint_every must be >= 0"),
        (cfg.torch_threads >= 0, "torch_threads must be >= 0"),
        (
            cfg.precision in ("fp32", "bf16"),
            f"precision must be fp32 or bf16 (got {cfg.precision!r})",
        ),
        *_atari_checks(cfg),
        *_posterior_checks(cfg),
    ]


def _atari_checks(cfg: Config) -> list[tuple[bool, str]]:
    """The Atari preprocessing fields."""
    return [
        (cfg.atari.frame_skip >= 1, f"atari.frame_skip must be >= 1 (got {cfg.atari.frame_skip})"),
        (
            cfg.atari.frame_stack >= 1,
            f"atari.frame_stack must be >= 1 (got {cfg.atari.frame_stack})",
        ),
        (cfg.atari.noop_max >= 0, f"atari.noop_max must be >= 0 (got {cfg.atari.noop_max})"),
        (
            cfg.atari.envpool_threads >= 0,
            f"atari.envpool_threads must be >= 0 (0: one per environment; got "
            f"{cfg.atari.envpool_threads})",
        ),
        (
            0.0 <= cfg.atari.repeat_action_probability <= 1.0,
            "atari.repeat_action_probability must be in [0, 1] (0.25: sticky actions, Machado et "
            f"al. 2018; got {cfg.atari.repeat_action_probability})",
        ),
        (
            cfg.atari.max_frames_per_episode >= 0,
            "atari.max_frames_per_episode must be >= 0 (0: no cap; got "
            f"{cfg.atari.max_frames_per_episode})",
        ),
    ]


def _posterior_checks(cfg: Config) -> list[tuple[bool, str]]:
    """The BLR posterior and adaptive-k fields."""
    return [
        (cfg.blr.prior_std > 0, f"blr.prior_std must be > 0 (got {cfg.blr.prior_std})"),
        (cfg.blr.noise_std > 0, f"blr.noise_std must be > 0 (got {cfg.blr.noise_std})"),
        (cfg.blr.cov_scale > 0, f"blr.cov_scale must be > 0 (got {cfg.blr.cov_scale})"),
        (0 < cfg.blr.forgetting <= 1, "blr.forgetting must be in (0, 1]"),
        (cfg.blr.posterior_every >= 1, "blr.posterior_every must be >= 1"),
        (cfg.blr.posterior_samples >= 1, "blr.posterior_samples must be >= 1"),
        (cfg.blr.redraw_every >= 1, "blr.redraw_every must be >= 1"),
        (
            1 <= cfg.adaptive_k.k_min <= cfg.adaptive_k.k_max,
            "adaptive_k bounds must satisfy 1 <= k_min <= k_max",
        ),
        (
            not cfg.adaptive_k.enabled or cfg.adaptive_k.k_min <= cfg.k <= cfg.adaptive_k.k_max,
            f"with adaptive k, the initial k ({cfg.k}) must lie in [k_min, k_max] = "
            f"[{cfg.adaptive_k.k_min}, {cfg.adaptive_k.k_max}]",
        ),
    ]


def _ob2i_rnd_checks(cfg: Config, spec: algorithms.Algorithm) -> list[tuple[bool, str]]:
    """OB2I and RND fields."""
    ob, rn = cfg.ob2i, cfg.rnd
    return [
        (ob.num_heads >= 2, f"ob2i.num_heads must be >= 2 (got {ob.num_heads})"),
        (0.0 <= ob.beta <= 1.0, f"ob2i.beta must be in [0, 1] (got {ob.beta})"),
        (ob.bonus_reward_weight >= 0, "ob2i.bonus_reward_weight must be >= 0"),
        (ob.bonus_next_weight >= 0, "ob2i.bonus_next_weight must be >= 0"),
        (ob.eval_policy in ("vote", "mean"), "ob2i.eval_policy must be 'vote' or 'mean'"),
        (
            rn.intrinsic_weight >= 0,
            f"rnd.intrinsic_weight must be >= 0 (got {rn.intrinsic_weight})",
        ),
        (rn.feature_dim >= 1, f"rnd.feature_dim must be >= 1 (got {rn.feature_dim})"),
        (rn.lr > 0, f"rnd.lr must be > 0 (got {rn.lr})"),
        (rn.obs_clip > 0, f"rnd.obs_clip must be > 0 (got {rn.obs_clip})"),
        (
            not spec.episodic or (cfg.k == 1 and not cfg.stride and not cfg.sample_recent),
            f"{cfg.algo} learns from whole episodes (episodic backward update): k must be 1 and "
            "stride and sample_recent off",
        ),
    ]


STEP_AGENTS = ("ddqn", "farsighter", "rnd")
"""Agents whose update the learner may capture as a CUDA graph or compile
(farsighter.agents.learner); OB2I's minibatches change size with each episode's tail (a graph or
a compilation per size) and NAF's update was never measured so: both run eagerly."""


def _algorithm_checks(cfg: Config, spec: algorithms.Algorithm) -> list[tuple[bool, str]]:
    """What the algorithm table allows, and the device."""
    adaptive = " and ".join(a.name for a in algorithms.TABLE if a.adaptive_k)
    device_ok = cfg.device in ("auto", "cpu", "cuda") or cfg.device.startswith("cuda:")
    step_algos = ", ".join(a.name for a in algorithms.TABLE if a.agent in STEP_AGENTS)
    return [
        (
            not cfg.adaptive_k.enabled or spec.adaptive_k,
            f"adaptive_k.enabled is only supported by --algo {adaptive}",
        ),
        (device_ok, f"unknown device '{cfg.device}'; accepted: auto, cpu, cuda, cuda:N"),
        (
            cfg.cuda_graph in ("auto", "on", "off"),
            f"cuda_graph must be auto, on or off (got {cfg.cuda_graph!r})",
        ),
        (
            cfg.overlap_env in ("auto", "on", "off"),
            f"overlap_env must be auto, on or off (got {cfg.overlap_env!r})",
        ),
        (
            cfg.gpu_replay in ("auto", "off"),
            f"gpu_replay must be auto or off (got {cfg.gpu_replay!r})",
        ),
        (
            cfg.cuda_graph != "on" or cfg.device != "cpu",
            "cuda_graph on needs a CUDA device (device cpu given); use auto or off",
        ),
        (
            cfg.cuda_graph != "on" or spec.agent in STEP_AGENTS,
            f"cuda_graph on is supported by --algo {step_algos}; use auto or off",
        ),
        (
            not cfg.compile or spec.agent in STEP_AGENTS,
            f"compile is supported by --algo {step_algos}",
        ),
        (
            not (cfg.compile and cfg.cuda_graph == "on"),
            "compile and cuda_graph on do not combine; use cuda_graph auto or off with compile",
        ),
        (
            cfg.k_target == "k" or spec.agent == "farsighter",
            "k_target max is only supported by --algo "
            + " and ".join(a.name for a in algorithms.TABLE if a.agent == "farsighter"),
        ),
    ]


def _naf_checks(cfg: Config, spec: algorithms.Algorithm) -> list[tuple[bool, str]]:
    """The continuous agents' fields."""
    n = cfg.naf
    return [
        (0.0 < n.tau <= 1.0, f"naf.tau must be in (0, 1] (got {n.tau})"),
        (n.updates_per_step >= 1, "naf.updates_per_step must be >= 1"),
        (n.noise_std >= 0, f"naf.noise_std must be >= 0 (got {n.noise_std})"),
        (0.0 < n.ou_theta <= 1.0, f"naf.ou_theta must be in (0, 1] (got {n.ou_theta})"),
        (
            len(n.hidden_sizes) >= 1 and all(h > 0 for h in n.hidden_sizes),
            "naf.hidden_sizes must be one or more positive integers",
        ),
        (n.prior_std > 0, f"naf.prior_std must be > 0 (got {n.prior_std})"),
        (n.init_sigma > 0, f"naf.init_sigma must be > 0 (got {n.init_sigma})"),
        (n.noise_std_eps > 0, f"naf.noise_std_eps must be > 0 (got {n.noise_std_eps})"),
        (n.elbo_every >= 1, "naf.elbo_every must be >= 1"),
        (n.elbo_steps >= 0, "naf.elbo_steps must be >= 0"),
        (n.elbo_batch >= 1, "naf.elbo_batch must be >= 1"),
        (n.elbo_lr > 0 and n.elbo_rho_lr > 0, "naf.elbo_lr and naf.elbo_rho_lr must be > 0"),
        (n.kl_weight >= 0, "naf.kl_weight must be >= 0"),
        (n.mu_penalty >= 0, "naf.mu_penalty must be >= 0"),
        (0.0 <= n.her_ratio <= 1.0, f"naf.her_ratio must be in [0, 1] (got {n.her_ratio})"),
        (
            not n.her or spec.actions == "continuous",
            "naf.her needs a continuous agent: "
            + algorithms.accepted(algorithms.names_for("continuous")),
        ),
        (
            spec.actions != "continuous" or n.elbo_batch <= cfg.buffer_size,
            f"naf.elbo_batch ({n.elbo_batch}) must not exceed buffer_size ({cfg.buffer_size})",
        ),
    ]
