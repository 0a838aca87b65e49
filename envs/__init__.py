"""envs: the Gymnasium crowd-navigation environment composing crowdsim, the predictor and the planner.

`import envs` registers `crowdnav/CrowdNav-v1` (`gymnasium.make("crowdnav/CrowdNav-v1", config=...)`).
v1: `info["episode_metrics"]` says `at_fault` ("robot", "pedestrian", "spawn") where v0 said `collision_kind`.
v0 is not registered: `gymnasium.make("crowdnav/CrowdNav-v0")` raises gymnasium's DeprecatedEnv naming v1.
Public API: `CrowdNavEnv`, `CrowdNavConfig` (with `ObservationConfig`, `RewardWeights`), `make_policy`,
`PolicyConfig`, `POLICIES`. torch (the predictor) is imported only when a predictor is used; rerun only by the observer.
"""

import gymnasium

from envs.config import CrowdNavConfig, ObservationConfig, RewardWeights
from envs.env import CrowdNavEnv
from envs.policies import POLICIES, PolicyConfig, make_policy

ENV_ID = "crowdnav/CrowdNav-v1"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="envs.env:CrowdNavEnv", disable_env_checker=False)

__all__ = ["ENV_ID", "POLICIES", "CrowdNavConfig", "CrowdNavEnv", "ObservationConfig", "PolicyConfig", "RewardWeights",
           "make_policy"]
