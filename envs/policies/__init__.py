"""The policies room: what drives the robot.

- `registry`: `PolicyConfig` -> `make_policy`, the registry `POLICIES` and the planner-based policies;
- `plugins`: user policies (`module:factory`) and stable-baselines3 agents (`sb3:PATH.zip`);
- `sb3_files`: SB3 agent files saved and loaded without unpickling, with the env's observation layout;
- `identity`: what identifies a policy's weights in results (fingerprints for resuming);
- `agents/`: the packaged agents (`ppo-crowdnav.zip`).

It imports the core room (`envs.env`, `envs.config`, ...) and never `envs.evaluation` or `envs.rl`.
"""

from envs.policies.registry import (
    AGENTS_DIR,
    DEFAULT_PREDICTOR,
    ENV_MPC,
    POLICIES,
    PREDICTOR_POLICIES,
    REPLAN_EVERY_STEPS,
    SCENE_TEMPLATE,
    GPGraphPolicy,
    PlannerPolicy,
    Policy,
    PolicyConfig,
    RandomPolicy,
    load_predictor_spec,
    make_policy,
    singleton_prediction,
)

__all__ = [
    "AGENTS_DIR", "DEFAULT_PREDICTOR", "ENV_MPC", "POLICIES", "PREDICTOR_POLICIES", "REPLAN_EVERY_STEPS",
    "SCENE_TEMPLATE", "GPGraphPolicy", "PlannerPolicy", "Policy", "PolicyConfig", "RandomPolicy",
    "load_predictor_spec", "make_policy", "singleton_prediction",
]
