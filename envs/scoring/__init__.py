"""scoring: the room of envs that measures an episode, below the core (it imports no other room of envs).

`metrics` (per-episode metrics, `EpisodeMetrics`), `social_metrics` (the social-navigation metrics, pure functions of
arrays), `collisions` (who is at fault for a contact), `geometry` (walls, rays, group hulls) and `kernels` (the
compiled per-step twins of geometry and the observation).
"""
