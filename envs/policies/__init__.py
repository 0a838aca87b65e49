"""The policies room: what drives the robot.

- `registry`: `PolicyConfig` -> `make_policy`, the registry `POLICIES`, the planner-based policies and `decide`,
  the one step of the episode loop (view -> `policy.act(view)` -> decision, applied by `env.step_decision`; `act`
  gives the env action instead, for a Gym loop);
- `plugins`: user policies (`module:factory`) and stable-baselines3 agents (`sb3:PATH.zip`);
- `sb3_files`: SB3 agent files saved and loaded without unpickling, with the env's observation layout;
- `wrappers`, `routed`, `shielded`: the suffixes `NAME+route` (heads for the global route's subgoal) and
  `NAME+shield` (decisions checked by the MPC's safety shield), for any policy but the MPC's;
- `identity`: what identifies a policy's weights in results (fingerprints for resuming);
- `agents/`: the packaged agents (`ppo-crowdnav.zip`).

It imports the core room (`envs.env`, `envs.config`, ...) and never `envs.evaluation` or `envs.rl`.
"""

from envs.policies.registry import (
    AGENTS_DIR,
    DEFAULT_PREDICTOR,
    ENV_MPC,
    PACKAGED_AGENTS,
    POLICIES,
    PREDICTOR_POLICIES,
    REPLAN_EVERY_STEPS,
    SCENE_TEMPLATE,
    GPGraphPolicy,
    LegacyPolicy,
    PlannerPolicy,
    Policy,
    PolicyConfig,
    RandomPolicy,
    act,
    decide,
    make_policy,
    singleton_prediction,
)

__all__ = [
    "AGENTS_DIR", "DEFAULT_PREDICTOR", "ENV_MPC", "PACKAGED_AGENTS", "POLICIES", "PREDICTOR_POLICIES",
    "REPLAN_EVERY_STEPS", "SCENE_TEMPLATE", "GPGraphPolicy", "LegacyPolicy", "PlannerPolicy", "Policy", "PolicyConfig",
    "RandomPolicy",
    "act", "decide", "make_policy", "singleton_prediction",
]
