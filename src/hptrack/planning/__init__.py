"""Global planner (paper Sec. IV-C): the tree search, the interface it asks of an MDP, the
sub-task MDP it searches, rollout policies, and the hierarchical planner that flies the plan."""

from hptrack.planning.backups import register_backup
from hptrack.planning.mdp import MdpKernels, register_mdp
from hptrack.planning.rollout import UniformRandom, register_policy
from hptrack.planning.search import SearchOptions, SearchResult, search_mdp
from hptrack.planning.subtask_mdp import PlanningProblem, SubtaskOptions
from hptrack.planning.subtask_search import search
from hptrack.planning.tree import MAX_ACTIONS, ActionStats

__all__ = [
    "MAX_ACTIONS",
    "ActionStats",
    "MdpKernels",
    "PlanningProblem",
    "SearchOptions",
    "SearchResult",
    "SubtaskOptions",
    "UniformRandom",
    "register_backup",
    "register_mdp",
    "register_policy",
    "search",
    "search_mdp",
]
