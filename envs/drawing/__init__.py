"""drawing: the room of envs that draws an episode, below the core (it imports no other room of envs).

`frame.SceneFrame` (what is drawn at one step, built by `CrowdNavEnv.frame()`), `render.render_rgb` (numpy-only RGB
images), `rerun_observer.RerunObserver` (rerun recordings; the only module of envs that imports rerun) and
`video` (MP4 / GIF files of episodes, `crowdnav evaluate --video N`; the only module that imports an encoder).
"""
