"""Typed run configuration, named presets and their sources.

A run is a pure function of its :class:`Config` and seed. Configs are frozen dataclasses with a
docstring per field (tyro turns those into ``--help`` text). Presets are named sets of field
values whose numbers cite their source; ``make_config`` layers them as

    field defaults  <-  preset  <-  algorithm  <-  preset for that algorithm  <-  explicit overrides

where "algorithm" is the values that define it (:mod:`farsighter.algorithms`), so a preset's
generic schedule never replaces them. A preset made for one algorithm (``Preset.algo``, e.g.
``bdqn``: that algorithm as its authors' code ran) is that algorithm's own variant: it is only
accepted with it and applies over its values. Nothing mutates a config after it is built.

The pieces: :mod:`~farsighter.config.fields` (the dataclasses), :mod:`~farsighter.config.presets`
(the presets and the layering), :mod:`~farsighter.config.checks` (``validate``) and
:mod:`~farsighter.config.files` (JSON in run directories).
"""

from farsighter.config.checks import validate
from farsighter.config.env_ids import env_id_of, make_config
from farsighter.config.fields import (
    AdaptiveKConfig,
    AtariConfig,
    BLRConfig,
    Config,
    NAFConfig,
    OB2IConfig,
    RNDConfig,
    RuntimeConfig,
)
from farsighter.config.files import config_from_dict, config_to_dict, load_config, save_config
from farsighter.config.presets import (
    PRESETS,
    Preset,
    config_layers,
    explain_config,
    is_atari_id,
    is_minatar_id,
    resolve_preset_name,
)

__all__ = [
    "PRESETS",
    "AdaptiveKConfig",
    "AtariConfig",
    "BLRConfig",
    "Config",
    "NAFConfig",
    "OB2IConfig",
    "Preset",
    "RNDConfig",
    "RuntimeConfig",
    "config_from_dict",
    "config_layers",
    "config_to_dict",
    "env_id_of",
    "explain_config",
    "is_atari_id",
    "is_minatar_id",
    "load_config",
    "make_config",
    "resolve_preset_name",
    "save_config",
    "validate",
]
