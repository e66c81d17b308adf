"""Sweep files: a grid of training runs written in TOML or YAML, parsed and expanded into trials.

A sweep file (``.toml``, or ``.yaml`` / ``.yml``) describes a grid; every combination of the
grid's lists is one *trial*, a training run with its own config and run directory. In TOML::

    name = "k-study"                 # required: the sweep's name; its directory defaults to
                                     #   sweeps/<name>
    description = "..."              # optional: free text

    [grid]                           # every combination of these lists is one trial
    agent = ["ddqn", "Farsighter-adaptive"]  # required: algorithm names or labels from [agents]
    env = ["CartPole-v1"]            # required: Gymnasium ids
    seed = [1, 2, 3]                 # required: integers >= 0
    k = [1, 10, 50]                  # optional: any Config field, dotted for nested fields
    "blr.noise_std" = [0.5, 1.0]     #   ("blr.noise_std"; TOML's unquoted dotted keys and
                                     #   [grid.blr] tables work too)

    [set]                            # optional: fixed values for every trial
    preset = "maze"                  #   (Config fields, and "preset")
    total_steps = 20000

    [agents.Farsighter-adaptive]     # optional: a labelled agent = an algorithm plus overrides
    algo = "farsighter"              #   required: its algorithm
    "adaptive_k.enabled" = true      #   any Config field, and "preset"

    [resources]                      # optional: what one trial needs
    cpus = 1                         # CPUs per trial (a number > 0; fractions allowed)
    gpus = 0                         # GPU fraction per trial (a number >= 0)
    max_concurrent = 0               # trials at once (0: no limit beyond the resources)
    retries = 3                      # times a failed or killed trial is restarted from its
                                     #   checkpoint (an integer >= 0)
    seeds_per_process = 1            # trials that differ only in seed trained together in one
                                     #   process, up to this many (an integer >= 1; batched as
                                     #   one computation where the agent allows it)

The same sweep in YAML::

    name: k-study
    grid:
      agent: [ddqn, Farsighter-adaptive]
      env: [CartPole-v1]
      seed: [1, 2, 3]
      k: [1, 10, 50]
      blr.noise_std: [0.5, 1.0]
    set: {preset: maze, total_steps: 20000}
    agents:
      Farsighter-adaptive: {algo: farsighter, adaptive_k.enabled: true}

Every grid value is a list, even of one value (``env = ["CartPole-v1"]``). A list-valued field
(``hidden_sizes``) takes a list per value: ``hidden_sizes = [[64, 64], [128, 128]]``.

**Agents.** ``grid.agent`` names algorithms (``farsighter algorithms``: ddqn, farsighter, ...)
or labels defined in ``[agents]``; a label defined there wins over an algorithm of the same
name, so ``[agents.ddqn]`` may retune ddqn. The label names the trial and its directory.

**Order of the values.** A trial's config is built by
:func:`farsighter.config.make_config` from its algorithm, environment and preset, with these
overrides applied in order, later ones winning:

    [set]  <-  the agent's overrides ([agents.<label>])  <-  the grid's values

and all of them over the preset and the algorithm's own values (so ``k`` in ``[set]`` replaces
farsighter's default k = 10). The preset is likewise the grid's ``preset`` if it is swept, else
the agent's, else ``[set]``'s, else ``auto``. Every trial runs on one torch thread
(``torch_threads = 1``, unless a section sets ``torch_threads``) and without a progress bar.

**Trials.** The grid expands with the agents outermost, then the environments, then the other
grid fields in the order of the file, and the seeds innermost. Each trial has a stable name,
its directory under the sweep's: ``<env>/<agent>[__<field>-<value>...]__s<seed>``, each part
slugged (``cartpole-v1/farsighter-adaptive__k-10__blr-noise-std-0-5__s1``). Two trials with
the same name (a value repeated in a grid list) are an error.

**Checks.** Everything is checked before anything runs, and every problem is one line naming
the file, the key and what is accepted (:class:`SweepError`): the file and its syntax (with the
parser's line and column), the sections, each value's type, the agents, the fields (``run_dir``,
``resume``, ``overwrite``, ``progress``, ``algo``, ``env`` and ``seed`` are the sweep's to set,
not a section's), the resources, and finally every trial's config through
:func:`farsighter.config.validate`.

YAML 1.1 (PyYAML) reads ``1e-4`` as a string: such strings are accepted for number fields.
"""

from __future__ import annotations

import dataclasses
import difflib
import itertools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

from farsighter import algorithms
from farsighter.config import Config, make_config, validate
from farsighter.config.field_types import field_value, leaf_fields
from farsighter.config.presets import runtime_key
from farsighter.errors import ConfigError, FarsighterError
from farsighter.rundir import slug

SECTIONS: tuple[str, ...] = ("name", "description", "grid", "set", "agents", "resources")
"""The accepted top-level keys of a sweep file."""

AXES: tuple[str, ...] = ("agent", "env", "seed")
"""The grid's required lists; every other grid key is a Config field."""

SUFFIXES: tuple[str, ...] = (".toml", ".yaml", ".yml")

# Config fields that a sweep sets itself, and what to write instead.
_RESERVED: dict[str, str] = {
    "algo": "choose algorithms with grid.agent (algorithm names, or [agents] labels with "
    "their own algo)",
    "env": "list environments in grid.env",
    "seed": "list seeds in grid.seed",
    "run_dir": "each trial runs in <sweep directory>/<trial name>",
    "resume": "an interrupted sweep resumes its trials from their checkpoints itself "
    "(see retries in [resources])",
    "overwrite": "an interrupted sweep resumes its trials from their checkpoints itself "
    "(see retries in [resources])",
    "progress": "trials run without a progress bar",
}


class SweepError(FarsighterError):
    """A sweep file that cannot be read, or that describes an invalid grid."""


@dataclass(frozen=True)
class Resources:
    """What one trial needs, and how the sweep schedules and retries trials."""

    cpus: float = 1.0
    """CPUs per trial (> 0; fractions allowed)."""
    gpus: float = 0.0
    """GPU fraction per trial (>= 0)."""
    max_concurrent: int = 0
    """Most trials running at once (0: no limit beyond the resources)."""
    retries: int = 3
    """Times a failed or killed trial is restarted from its checkpoint (>= 0)."""
    seeds_per_process: int = 1
    """Trials that differ only in seed trained together in one process, up to this many
    (:func:`farsighter.seeds.train_seeds`: one batched computation where the agent allows it,
    one after another otherwise); each keeps its own trial directory and resumes on its own."""


@dataclass(frozen=True)
class Trial:
    """One training run of a sweep: an agent on an environment with one seed and grid point."""

    agent: str
    """The agent's label: an algorithm name or a label from ``[agents]``."""
    algo: str
    """Its algorithm."""
    env: str
    """The Gymnasium id."""
    seed: int
    """The run's seed."""
    overrides: tuple[tuple[str, Any], ...]
    """Config values given to make_config besides algo, env and preset: ``[set]``, then the
    agent's, then the grid's (later ones win), dotted keys for nested fields."""
    preset: str
    """The preset: the grid's, else the agent's, else ``[set]``'s, else auto."""
    swept: tuple[tuple[str, Any], ...]
    """The grid's values of this trial other than agent, env and seed, in the file's order."""

    @property
    def name(self) -> str:
        """Stable directory name: ``<env>/<agent>[__<field>-<value>...]__s<seed>``, slugged."""
        parts = [slug(self.agent)]
        parts += [slug(f"{key}-{_format(value)}") for key, value in self.swept]
        parts.append(f"s{self.seed}")
        return f"{slug(self.env)}/" + "__".join(parts)

    def config(self, run_dir: str | Path) -> Config:
        """The trial's config, running in ``run_dir`` on one torch thread (unless the sweep sets
        ``torch_threads``) without a progress bar."""
        values: dict[str, Any] = {"torch_threads": 1}
        values.update(self.overrides)
        values.update(progress=False, seed=self.seed, run_dir=str(run_dir))
        return make_config(self.algo, self.env, self.preset, **values)


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep file: its name, description, expanded trials and resources."""

    name: str
    description: str
    trials: tuple[Trial, ...]
    resources: Resources
    source: str
    """Where it was read from (the path, as given), for messages."""

    @property
    def default_dir(self) -> Path:
        """``sweeps/<name>``: where the sweep runs unless told otherwise."""
        return Path("sweeps") / self.name


# --------------------------------------------------------------------------------------------
# Reading a file
# --------------------------------------------------------------------------------------------


def load_spec(path: str | Path) -> SweepSpec:
    """Read, check and expand a sweep file (``.toml``, ``.yaml`` or ``.yml``)."""
    file = Path(path)
    source = str(path)
    if not file.exists():
        raise SweepError(f"{source}: no such sweep file")
    if not file.is_file():
        raise SweepError(f"{source}: not a file; give a .toml, .yaml or .yml sweep file")
    suffix = file.suffix.lower()
    if suffix not in SUFFIXES:
        raise SweepError(
            f"{source}: unknown sweep file type '{suffix or '(none)'}'; accepted: "
            + ", ".join(SUFFIXES)
        )
    try:
        text = file.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SweepError(f"{source}: cannot read the sweep file: {_one_line(exc)}") from None
    data = _parse_toml(text, source) if suffix == ".toml" else _parse_yaml(text, source)
    return parse_spec(data, source)


def _parse_toml(text: str, source: str) -> Any:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10: the tomli backport has the same interface
        try:
            import tomli as tomllib  # type: ignore[no-redef]
        except ModuleNotFoundError:
            raise SweepError(
                f"{source}: TOML sweep files need Python >= 3.11 or tomli (pip install tomli)"
            ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SweepError(f"{source}: malformed TOML: {_one_line(exc)}") from None


def _parse_yaml(text: str, source: str) -> Any:
    try:
        import yaml
    except ModuleNotFoundError:
        raise SweepError(
            f"{source}: YAML sweep files need PyYAML (pip install pyyaml); or write it in TOML"
        ) from None
    try:
        return yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f" (at line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        what = ": ".join(str(part) for part in (exc.context, exc.problem) if part)
        raise SweepError(f"{source}: malformed YAML: {_one_line(what or exc)}{where}") from None
    except yaml.YAMLError as exc:
        raise SweepError(f"{source}: malformed YAML: {_one_line(exc)}") from None


def _one_line(exc: object) -> str:
    return " ".join(str(exc).split())


# --------------------------------------------------------------------------------------------
# Checking and expanding
# --------------------------------------------------------------------------------------------


def parse_spec(data: Any, source: str) -> SweepSpec:
    """Check the parsed contents of a sweep file and expand its grid into trials.

    ``source`` names the file in messages. Raises :class:`SweepError` with one line.
    """

    def fail(message: str) -> NoReturn:
        raise SweepError(f"{source}: {message}")

    if not isinstance(data, Mapping):
        fail(
            f"the top level must be a table of keys (got {_kind(data)}); accepted keys: "
            + ", ".join(SECTIONS)
        )
    for key in data:
        if key not in SECTIONS:
            fail(f"unknown top-level key '{key}'; accepted: {', '.join(SECTIONS)}")

    if "name" not in data:
        fail("missing 'name': give the sweep a name (name = \"k-study\")")
    name = data["name"]
    if not isinstance(name, str) or not name.strip():
        fail(f"name must be a non-empty string (got {name!r})")
    if "/" in name or "\\" in name or name.strip() in (".", ".."):
        fail(f"name must be usable as a directory name, without '/' or '\\' (got {name!r})")
    description = data.get("description")
    description = "" if description is None else description
    if not isinstance(description, str):
        fail(f"description must be a string (got {description!r})")

    set_values = _section_values(data.get("set", {}), "set", source)
    agents = _agents(data.get("agents", {}), source)
    resources = _resources(data.get("resources", {}), source)

    if "grid" not in data:
        fail("missing [grid]: give at least grid.agent, grid.env and grid.seed")
    grid = _grid(data["grid"], source)

    labels = _grid_agents(grid, agents, fail)
    swept_keys = [key for key in grid if key not in AXES]
    trials: list[Trial] = []
    product = itertools.product(
        labels, grid["env"], *(grid[key] for key in swept_keys), grid["seed"]
    )
    for (label, algo, agent_values), env, *point, seed in product:
        swept = tuple(zip(swept_keys, point, strict=True))
        values = {**set_values, **agent_values, **dict(swept)}
        preset = values.pop("preset", "auto")
        trials.append(Trial(label, algo, env, seed, tuple(values.items()), preset, swept))

    seen: dict[str, Trial] = {}
    for trial in trials:
        if trial.name in seen:
            fail(
                f"two trials have the same name '{trial.name}': a grid list repeats a value, "
                "or two values or agent labels give the same directory name"
            )
        seen[trial.name] = trial

    for trial in trials:
        try:
            validate(trial.config(run_dir=""))
        except ConfigError as exc:
            fail(f"trial {trial.name}: {exc}")

    return SweepSpec(name, description, tuple(trials), resources, source)


def _grid_agents(
    grid: dict[str, list[Any]],
    agents: dict[str, tuple[str, dict[str, Any]]],
    fail: Callable[[str], NoReturn],
) -> list[tuple[str, str, dict[str, Any]]]:
    """(label, algorithm, overrides with the preset) of every grid agent; the grid's envs and
    seeds checked too."""
    labels: list[tuple[str, str, dict[str, Any]]] = []  # label, algo, overrides (with preset)
    for label in grid["agent"]:
        if not isinstance(label, str):
            fail(f"grid.agent: agents are names (got {label!r})")
        if label in agents:
            algo, overrides = agents[label]
        elif label in algorithms.NAMES:
            algo, overrides = label, {}
        else:
            defined = ", ".join(agents) or "none defined"
            fail(
                f"grid.agent: unknown agent '{label}'; accepted: algorithm names "
                f"({algorithms.accepted()}) or labels from [agents] ({defined})"
            )
        labels.append((label, algo, overrides))
    for env in grid["env"]:
        if not isinstance(env, str) or not slug(env):
            fail(f"grid.env: environments are Gymnasium ids such as 'CartPole-v1' (got {env!r})")
    for seed in grid["seed"]:
        if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
            fail(f"grid.seed: seeds are integers >= 0 (got {seed!r})")
    return labels


def _grid(raw: Any, source: str) -> dict[str, list[Any]]:
    """The grid's lists, in the file's order: agent, env, seed as given, fields checked."""
    if not isinstance(raw, Mapping):
        raise SweepError(f"{source}: [grid] must be a table of lists (got {_kind(raw)})")
    for axis in AXES:
        if axis not in raw:
            raise SweepError(
                f"{source}: missing grid.{axis}: [grid] needs agent, env and seed lists "
                f"(e.g. {axis} = {_EXAMPLES[axis]})"
            )
    grid: dict[str, list[Any]] = {}
    for key, value in raw.items():
        if key in AXES:
            grid[key] = _list(value, f"grid.{key}", source)
    for key, value in _flatten(
        {k: v for k, v in raw.items() if k not in AXES}, "grid", source, lists=True
    ).items():
        where = f"grid.{key}"
        grid[key] = [_coerce(v, key, where, source) for v in _list(value, where, source)]
    return grid


_EXAMPLES = {"agent": '["ddqn", "farsighter"]', "env": '["CartPole-v1"]', "seed": "[1, 2, 3]"}


def _list(value: Any, where: str, source: str) -> list[Any]:
    if not isinstance(value, list):
        raise SweepError(
            f"{source}: {where} must be a list of values (got {value!r}); write [{value!r}] "
            "for one value, or set it in [set]"
        )
    if not value:
        raise SweepError(f"{source}: {where} is empty: give at least one value")
    return value


def _section_values(raw: Any, section: str, source: str) -> dict[str, Any]:
    """A table of Config fields (``[set]`` or one ``[agents.X]`` without algo), checked."""
    if not isinstance(raw, Mapping):
        raise SweepError(f"{source}: [{section}] must be a table of fields (got {_kind(raw)})")
    values = _flatten(raw, section, source, lists=False)
    return {key: _coerce(v, key, f"{section}.{key}", source) for key, v in values.items()}


def _agents(raw: Any, source: str) -> dict[str, tuple[str, dict[str, Any]]]:
    """``[agents]``: per label, its algorithm and overrides (``preset`` among them)."""
    if not isinstance(raw, Mapping):
        raise SweepError(f"{source}: [agents] must be a table of agents (got {_kind(raw)})")
    agents: dict[str, tuple[str, dict[str, Any]]] = {}
    for label, table in raw.items():
        where = f"agents.{label}"
        if not isinstance(label, str) or not slug(label):
            raise SweepError(
                f"{source}: agent label {label!r} must be a string with a letter or digit"
            )
        if not isinstance(table, Mapping):
            raise SweepError(
                f"{source}: [{where}] must be a table with algo and overrides (got {_kind(table)})"
            )
        if "algo" not in table:
            raise SweepError(
                f"{source}: [{where}] has no algo: give algo = one of {algorithms.accepted()}"
            )
        algo = table["algo"]
        if algo not in algorithms.NAMES:
            raise SweepError(
                f"{source}: {where}.algo: unknown algorithm {algo!r}; accepted: "
                f"{algorithms.accepted()}"
            )
        rest = {k: v for k, v in table.items() if k != "algo"}
        agents[label] = (algo, _section_values(rest, where, source))
    return agents


def _resources(raw: Any, source: str) -> Resources:
    if not isinstance(raw, Mapping):
        raise SweepError(f"{source}: [resources] must be a table (got {_kind(raw)})")
    accepted = [f.name for f in dataclasses.fields(Resources)]
    for key in raw:
        if key not in accepted:
            raise SweepError(
                f"{source}: unknown key resources.{key}; accepted: {', '.join(accepted)}"
            )
    checks: dict[str, tuple[bool, str]] = {
        "cpus": (False, "a number > 0 (CPUs per trial)"),
        "gpus": (False, "a number >= 0 (GPU fraction per trial)"),
        "max_concurrent": (True, "an integer >= 0 (0: no limit)"),
        "retries": (True, "an integer >= 0"),
        "seeds_per_process": (True, "an integer >= 1"),
    }
    for key, value in raw.items():
        integer, want = checks[key]
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        ok = number and (isinstance(value, int) if integer else True)
        ok = ok and (value > 0 if key in ("cpus", "seeds_per_process") else value >= 0)
        if not ok:
            raise SweepError(f"{source}: resources.{key} must be {want} (got {value!r})")
    default = Resources()
    return Resources(
        cpus=float(raw.get("cpus", default.cpus)),
        gpus=float(raw.get("gpus", default.gpus)),
        max_concurrent=int(raw.get("max_concurrent", default.max_concurrent)),
        retries=int(raw.get("retries", default.retries)),
        seeds_per_process=int(raw.get("seeds_per_process", default.seeds_per_process)),
    )


# --------------------------------------------------------------------------------------------
# Config fields
# --------------------------------------------------------------------------------------------


def _flatten(raw: Mapping[Any, Any], section: str, source: str, *, lists: bool) -> dict[str, Any]:
    """Check a section's keys as Config fields; nested tables (TOML's ``[set.blr]`` or unquoted
    ``blr.noise_std = ...``) become dotted keys. ``lists``: the grid, where values are lists."""
    leaves, groups = leaf_fields()
    out: dict[str, Any] = {}
    for key, value in raw.items():
        if not isinstance(key, str):
            raise SweepError(f"{source}: {section}: keys are field names (got {key!r})")
        key = runtime_key(key)  # the runtime section's fields go by their plain names too
        if key in groups and isinstance(value, Mapping):
            for sub, sub_value in value.items():
                out.update(_flatten({f"{key}.{sub}": sub_value}, section, source, lists=lists))
            continue
        if key in _RESERVED:
            raise SweepError(
                f"{source}: {section}.{key} cannot be set in a sweep: {_RESERVED[key]}"
            )
        if key in groups:
            example = next(name for name in leaves if name.startswith(key + "."))
            raise SweepError(
                f"{source}: {section}.{key} is a group of fields: set them one by one, dotted "
                f"('{example}')"
            )
        if key not in leaves:
            close = difflib.get_close_matches(key, leaves, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            where = "[grid] takes agent, env, seed and " if lists else ""
            raise SweepError(
                f"{source}: {section}: unknown config field '{key}'{hint}; accepted: "
                f"{where}Config fields, dotted for nested ones ('blr.noise_std'); see "
                "farsighter train --help"
            )
        out[key] = value
    return out


def _coerce(value: Any, key: str, where: str, source: str) -> Any:
    """A value as its field takes it (:func:`farsighter.config.field_types.field_value`)."""
    value, want = field_value(key, value)
    if want:
        grid = " (one list per grid value)" if where.startswith("grid.") and "list" in want else ""
        raise SweepError(f"{source}: {where} must be {want}{grid} (got {value!r})")
    return value


def _format(value: Any) -> str:
    """A value as it appears in a trial's name: ``10``, ``0.5``, ``64-64``, ``true``."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return "-".join(map(str, value))
    return str(value)


def _kind(value: Any) -> str:
    return "nothing" if value is None else f"{type(value).__name__} {value!r}"[:80]
