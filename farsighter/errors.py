"""Errors a user can fix: the CLI prints them as one line and exits with code 2."""


class FarsighterError(Exception):
    """Base class of errors caused by input (config, environment id, run directory)."""


class ConfigError(FarsighterError):
    """An invalid configuration value or combination."""


class RunDirError(FarsighterError):
    """A run directory that exists, is missing, or holds a corrupt checkpoint."""


class EnvError(FarsighterError):
    """An environment id that cannot be made, or a space an algorithm cannot handle."""
