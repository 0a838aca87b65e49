"""The evaluation room: running policies over fixed episodes and reporting them.

- `episode`: one episode (`run_episode`) and one task (`EpisodeTask` -> `run_task` -> `EpisodeRecord`);
- `pool`: where tasks run (`run_tasks`: this process, the local process pool, or Ray);
- `records`: the typed per-episode record and its append-only store (what a run resumes from);
- `stats`: rates with intervals, paired comparisons;
- `evaluate`: `crowdnav evaluate` (policies x seeds in one env config);
- `suite`, `suites/`: the versioned benchmark suites; `benchmark`: `crowdnav benchmark`;
- `report`, `leaderboard`: tables and figures.

It imports the core and policies rooms, never `envs.rl`.
"""
