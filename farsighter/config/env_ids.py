"""The environment a config names: a Gymnasium id, or an environment object made from one
(``gymnasium.make``), whose registered id is what the config keeps (a run directory stores ids,
and every process makes its own environments from them)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from farsighter.config import presets
from farsighter.config.fields import Config
from farsighter.errors import ConfigError

if TYPE_CHECKING:
    import gymnasium as gym

PASS_AN_ID = (
    "pass an id (such as 'CartPole-v1'), or register it with "
    "gymnasium.register(id='MyEnv-v0', entry_point=...) and pass that id"
)


def env_id_of(env: Any) -> str:
    """``env`` itself when it is an id; for an environment object its ``spec.id``, refused (one
    line) where the id and its constructor arguments (:func:`constructor_kwargs`, which a config
    keeps as ``env_kwargs``) would not make the same environment again: none registered, another
    episode limit, or wrappers around it."""
    if isinstance(env, str):
        return env
    if not (callable(getattr(env, "step", None)) and callable(getattr(env, "reset", None))):
        raise ConfigError(
            "env must be a Gymnasium environment id such as 'CartPole-v1' or an environment "
            f"made by gymnasium.make (got {type(env).__name__})"
        )
    import gymnasium as gym

    spec = getattr(env, "spec", None)
    name = type(getattr(env, "unwrapped", env)).__name__
    if spec is None or spec.id not in gym.registry:
        raise ConfigError(f"this {name} environment has no registered Gymnasium id; {PASS_AN_ID}")
    registered, made = gym.spec(spec.id), f"this {spec.id} environment was made"
    steps, limit = spec.max_episode_steps, registered.max_episode_steps
    if steps != limit and steps is None:  # unwrapped, say
        raise ConfigError(
            f"{made} without its id's time limit ({limit} steps), which a run made from the id "
            "has; pass the id (with max_episode_steps=N for another limit)"
        )
    if steps != limit:
        raise ConfigError(
            f"{made} with max_episode_steps={steps}; pass its id with max_episode_steps={steps}"
        )
    if spec.additional_wrappers:
        wrappers = ", ".join(w.name for w in spec.additional_wrappers)
        raise ConfigError(
            f"{made} with wrappers its id does not carry ({wrappers}); register an id whose "
            "entry point makes the wrapped environment and pass that id"
        )
    return str(spec.id)


def constructor_kwargs(env: Any) -> dict[str, Any]:
    """The arguments an environment made by gymnasium.make was given beyond its id's (its
    ``env_kwargs``; ``render_mode`` aside, which each use chooses)."""
    import gymnasium as gym

    spec, registered = env.spec, gym.spec(env.spec.id)
    return {
        key: value
        for key, value in spec.kwargs.items()
        if key != "render_mode"
        and (key not in registered.kwargs or registered.kwargs[key] != value)
    }


def make_config(
    algo: str = "ddqn",
    env: str | gym.Env[Any, Any] = "CartPole-v1",
    preset: str = "auto",
    **overrides: Any,
) -> Config:
    """:func:`farsighter.config.presets.make_config` (field defaults <- preset <- algorithm <-
    the preset's values for it <- ``overrides``), where ``env`` is an id or an environment made
    from one (:func:`env_id_of`).

    ``overrides`` use field names; nested fields are written ``blr__prior_std`` or passed in a
    dict as ``{"blr.prior_std": ...}`` via ``**{"blr.prior_std": 0.1}``. The runtime section's
    fields also go by their plain names (``device="cpu"``, ``torch_threads=1``), as on the
    command line."""
    env_id = env_id_of(env)
    made_with = {} if isinstance(env, str) else constructor_kwargs(env)
    if made_with:  # an environment made with arguments: they travel with the config
        if "env_kwargs" in overrides:
            raise ConfigError(
                f"env_kwargs given twice: the {env_id} environment was made with {made_with}; "
                "pass its id with env_kwargs, or the environment"
            )
        overrides = {**overrides, "env_kwargs": made_with}
    return presets.make_config(algo, env_id, preset, **overrides)
