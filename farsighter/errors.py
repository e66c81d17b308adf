"""Errors a user can fix: the CLI prints them as one line and exits with code 2."""


class FarsighterError(Exception):
    """Base class of errors caused by input (config, environment id, run directory)."""


class ConfigError(FarsighterError):
    """An invalid configuration value or combination."""


class RunDirError(FarsighterError):
    """A run directory that exists, is missing, or holds a corrupt checkpoint."""


class EnvError(FarsighterError):
    """An environment id that cannot be made, or a space an algorithm cannot handle."""


class Diverged(FarsighterError):
    """Training whose values left the floating-point range (the TD loss or the posterior's
    statistics NaN or inf): the config's values make the updates grow without bound."""

    def __init__(self, what: str) -> None:
        super().__init__(
            f"training diverged: {what}; these settings make the updates grow without bound "
            "(smaller steps, --lr, or for the Bayesian agents a narrower prior, --blr.prior-std, "
            "are what to try); what the run directory saved before is kept"
        )


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM stopped ``farsighter train`` (:mod:`farsighter.interrupt`): the CLI
    prints the message as one line and exits with 128 + ``signum`` (130, 143). A
    KeyboardInterrupt, so that what handles Ctrl-C handles it, and no ``except Exception`` on
    the way turns it into another error."""

    def __init__(self, signum: int, message: str) -> None:
        super().__init__(message)
        self.signum = signum
