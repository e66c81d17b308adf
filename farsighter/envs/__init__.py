"""Environments: the factory every agent uses, Atari preprocessing and the bridge maze."""

from farsighter.envs.factory import (
    check_spaces,
    frame_stack_of,
    make_env,
    make_eval_envs,
    make_vector_env,
)

__all__ = ["check_spaces", "frame_stack_of", "make_env", "make_eval_envs", "make_vector_env"]
