"""How agents explore, as objects beside them: epsilon-greedy
(:mod:`farsighter.exploration.epsilon`), Thompson draws and their redraw schedules
(:mod:`farsighter.exploration.thompson`), the episode visits of the ``revisit`` schedule
(:mod:`farsighter.exploration.revisit`), and when the targets' optimism ends and what the cut
target records (:mod:`farsighter.exploration.optimism`)."""

from farsighter.exploration.epsilon import EpsilonGreedy
from farsighter.exploration.thompson import SCHEDULES, Schedule, ThompsonExploration

__all__ = ["SCHEDULES", "EpsilonGreedy", "Schedule", "ThompsonExploration"]
