"""The RL room: training agents on the env (the `rl` extra: stable-baselines3).

- `train`: `crowdnav train` (PPO, optional DAgger/behaviour-cloning warm start, resumable);
- `monitor`: progress, evaluation and checkpoints during training;
- `setting`: training in a benchmark suite's cell, seeds disjoint from the suites', the decision period wrapper;
- `imitation`: expert demonstrations and behaviour cloning;
- `extractor`: the set-aware features extractor (attention over pedestrians);
- `lagrangian`, `cost`: constrained PPO (PPO-Lagrangian, `crowdnav train --constraint`) and the cost it bounds.

It may import every other room of `envs`; nothing outside it imports it except `envs.cli`.
"""
