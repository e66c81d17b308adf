"""How agents explore, as objects beside them: Thompson draws and their redraw schedules
(:mod:`farsighter.exploration.thompson`), the episode visits of the ``revisit`` schedule
(:mod:`farsighter.exploration.revisit`)."""

from farsighter.exploration.thompson import SCHEDULES, Schedule, ThompsonExploration

__all__ = ["SCHEDULES", "Schedule", "ThompsonExploration"]
