"""Exploration policies: several interactions on one hose, votes merged (thesis chapter 6).

    from cablesim.policies import ExploreConfig, PerturbConfig, explore
    res = explore(ExploreConfig(seed=0, perturb=PerturbConfig(enabled=True)), out="runs/demo")
    print(res.summary())

Modules: ``config`` (ExploreConfig), ``explore`` (the loop, the random-grasp and push
baselines), ``merge`` (votes carried between target frames), ``perturb`` (seeded disturbance
of neighbouring hoses during actions), ``report`` (pictures, video, metrics).
Importing this package does not import MuJoCo; :func:`explore` does.
"""

from .config import STRATEGIES, ExploreConfig
from .merge import VoteMerger, warp_votes
from .perturb import PerturbConfig

__all__ = [
    "STRATEGIES",
    "ExploreConfig",
    "PerturbConfig",
    "VoteMerger",
    "explore",
    "warp_votes",
]


def __getattr__(name: str):  # lazy: explore imports MuJoCo
    if name == "explore":
        from .explore import explore

        return explore
    raise AttributeError(name)
