"""A config as JSON: written into every run directory and read back on resume."""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

from farsighter import jsonio
from farsighter.config.fields import Config, RuntimeConfig
from farsighter.errors import ConfigError

# --------------------------------------------------------------------------------------------
# JSON round trip (the run directory stores the resolved config).
# --------------------------------------------------------------------------------------------


def config_to_dict(cfg: Config) -> dict[str, Any]:
    return dataclasses.asdict(cfg)


def config_from_dict(data: dict[str, Any]) -> Config:
    def build(cls: Any, values: dict[str, Any]) -> Any:
        kwargs: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            if f.name not in values:
                continue
            value = values[f.name]
            if (
                dataclasses.is_dataclass(f.default_factory)
                if callable(f.default_factory)
                else False
            ):
                value = build(f.default_factory, value)
            elif isinstance(value, list):
                value = tuple(value)
            kwargs[f.name] = value
        return cls(**kwargs)

    if "runtime" not in data:  # written before the runtime section: its fields at the top
        runtime = {f.name for f in dataclasses.fields(RuntimeConfig)}
        data = {**data, "runtime": {k: v for k, v in data.items() if k in runtime}}
    return build(Config, data)


def save_config(cfg: Config, path: Path) -> None:
    """Write atomically: a crash mid-write leaves the previous file intact."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(jsonio.dumps(config_to_dict(cfg)) + "\n")
    os.replace(tmp, path)


def load_config(path: Path) -> Config:
    try:
        return config_from_dict(json.loads(path.read_text()))
    except (OSError, ValueError, TypeError) as exc:
        raise ConfigError(f"cannot read run config {path}: {exc}") from None
