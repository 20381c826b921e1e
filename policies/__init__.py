"""Exploration policies: several interactions on one hose, votes merged (thesis chapter 6).

    from cablesim.policies import ExploreConfig, PerturbConfig, explore
    res = explore(ExploreConfig.of(seed=0, perturb=PerturbConfig(enabled=True)), out="runs/demo")
    print(res.summary())

Modules: ``config`` (ExploreConfig), ``explore`` (the loop over a simulated or real session,
the random-grasp and push baselines), ``merge`` (votes carried between target frames),
``report`` (pictures, video, metrics).
"""

from cablesim.sim.config import PerturbConfig

from .config import STRATEGIES, ExploreConfig
from .explore import explore
from .merge import VoteMerger, warp_votes

__all__ = [
    "STRATEGIES",
    "ExploreConfig",
    "PerturbConfig",
    "VoteMerger",
    "explore",
    "warp_votes",
]
