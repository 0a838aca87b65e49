"""crowds: the room of envs that supplies the pedestrians, below the core (it imports no other room of envs).

`crowd` (the `Crowd` protocol the env talks to, and `SimCrowd`, crowdsim's social-force crowd), `orca` (CrowdNav's
ORCA humans, `OrcaCrowd` and its `OrcaCrowdConfig`; `rvo`, the one module that imports pyrvo), `replay` (`ReplayCrowd`,
a recorded ETH/UCY crowd; `replay_overlay`, time-shifted copies of one) and `models`, the registry the env config
names a crowd by (`make_crowd`). The crowds read an env config only through the protocols `models.CrowdSetting` and
`orca.OrcaSetting`; `envs.config` imports their names and config types, never the other way.
"""
