"""crowdsim: a pymunk social-force crowd simulator with walking groups and ground-truth group labels.

Public API: `SimConfig` (and its parts), `CrowdSimulator`, `CrowdState`, `make_scenario`, `SCENARIOS`,
`generate`, `make_dataset`.
"""

__version__ = "0.1.0"

from crowdsim.config import GroupConfig, GroupForceParams, RobotSlot, SimConfig, SocialForceParams
from crowdsim.scenarios import SCENARIOS, make_scenario
from crowdsim.sim import CrowdSimulator
from crowdsim.state import CrowdState

__all__ = [
    "SCENARIOS",
    "CrowdSimulator",
    "CrowdState",
    "GroupConfig",
    "GroupForceParams",
    "RobotSlot",
    "SimConfig",
    "SocialForceParams",
    "__version__",
    "make_scenario",
]
