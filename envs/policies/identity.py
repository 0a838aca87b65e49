"""The weight files a policy config loads, and one digest of their bytes for episode fingerprints.

A benchmark or evaluation folder resumes by fingerprint (`envs.evaluation.episode.fingerprint`). The policy config names
its predictor or agent, but a name is not its weights: retraining `gpgraph-stgcnn-synthetic` or re-packaging
`ppo-crowdnav` keeps the name. The digest of the files behind the names goes into the fingerprint, so records
made with other weights are refused on resume instead of being mixed silently into a new leaderboard.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path
from typing import Any

from envs.factories import is_plugin
from envs.policies import AGENTS_DIR, POLICIES, PolicyConfig
from envs.policies.plugins import SB3_PREFIX, parse_sb3
from envs.policies.wrappers import base_name
from predictor.checkpoints import checkpoint_file  # torch-free
from predictor.group_rules import split_group_rule  # torch-free


def artifact_files(cfg: PolicyConfig) -> list[Path]:
    """The weight files `make_policy(cfg)` loads: the predictor's checkpoint (mpc-gpgraph, plug-in policies
    given a predictor), the packaged agent of a registry agent policy, or the `sb3:` file. Names that are no
    file (constant velocity, a typo) give none here; loading them fails later, with its own message."""
    cfg = replace(cfg, name=base_name(cfg.name))  # NAME+route+shield loads NAME's files
    files: list[Path | None] = []
    predictor = cfg.predictor_used()
    if predictor is not None and not is_plugin(predictor):
        try:
            name = split_group_rule(predictor)[0]  # "NAME+RULE": NAME's weights (the rule is in the config)
        except ValueError:
            name = predictor  # an unknown rule: loading fails later, with its own message
        files.append(checkpoint_file(name))
    if cfg.name.startswith(SB3_PREFIX):
        files.append(parse_sb3(cfg.name)[1])
    elif cfg.name in POLICIES and (AGENTS_DIR / f"{cfg.name}.zip").is_file():
        files.append(AGENTS_DIR / f"{cfg.name}.zip")
    return [f for f in files if f is not None and f.is_file()]


def artifact_digest(cfg: PolicyConfig) -> str | None:
    """sha256 (16 hex digits) of the bytes of `artifact_files(cfg)`, None when the config loads no file."""
    files = artifact_files(cfg)
    if not files:
        return None
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


# MPCConfig fields added after records existed, with their defaults: left out of the fingerprint while at the
# default, so that records made before a field existed still match a config that does not use it
# ("spacetime", removed, was None in all)
LATER_MPC_FIELDS: dict[str, Any] = {"n_starts": 1, "guidance": None, "foresight": None}
# MPCConfig fields removed after records existed (layers tried and not adopted, docs/decisions/planner-settings.md,
# "Removed layers"), with the JSON value each had at its default (every record's: they were off in every suite): put
# back into the fingerprinted config, so that the fingerprints of records made while they existed do not change
REMOVED_MPC_FIELDS: dict[str, Any] = {
    "lane": None, "rank_peds_by": "distance",
    "speed_cap_gain_per_s": "inf", "speed_cap_min_mps": 0.3, "speed_cap_half_angle_deg": 90.0,
    "speed_cap_lookahead_s": 0.0, "shield_hold_weight": 0.0, "shield_group_weight": 0.0, "shield_group_margin_m": 0.2,
}


def policy_identity(cfg: PolicyConfig) -> list[Any]:
    """What identifies a policy in an episode fingerprint: its config (JSON, without the `LATER_MPC_FIELDS` at
    their defaults, with the `REMOVED_MPC_FIELDS` at theirs) and, when it loads weight files, their digest (left out
    otherwise, so the fingerprints of such policies are those made before digests)."""
    conf = cfg.to_json()
    if isinstance(conf.get("mpc"), dict):
        kept = {k: v for k, v in conf["mpc"].items() if k not in LATER_MPC_FIELDS or v != LATER_MPC_FIELDS[k]}
        conf["mpc"] = {**REMOVED_MPC_FIELDS, **kept}
    digest = artifact_digest(cfg)
    return [conf] if digest is None else [conf, digest]


def agent_observation(cfg: PolicyConfig) -> dict[str, Any]:
    """The `ObservationConfig` fields an SB3 agent policy (`sb3:` or a packaged agent) was trained to observe
    beyond what every policy sees, read from its saved layout: `wall_rays` (its `walls` key), and with predictions
    `predictions`, `n_prediction_samples`, `prediction_source`, the `predictor` its training run named, and with their
    calibration `prediction_calibration`, `calibration_alpha`. {} for other policies and agents without them."""
    from envs.policies.sb3_files import read_agent, saved_signature

    files = [f for f in artifact_files(cfg) if f.suffix == ".zip"]
    cfg = replace(cfg, name=base_name(cfg.name))
    if not files or not (cfg.name.startswith(SB3_PREFIX) or cfg.name in POLICIES):
        return {}
    try:
        data, layout = read_agent(files[-1])
    except ValueError:
        return {}  # not an agent file: loading it fails later, with its own message
    saved = saved_signature(data, layout) or {}
    keys, out = saved.get("keys", {}), {}
    if keys.get("walls"):
        out["wall_rays"] = int(keys["walls"][0])
    if "predictions" in keys:
        trained = ((layout or {}).get("meta") or {}).get("train_config") or {}
        out.update(predictions=True, n_prediction_samples=int(keys["predictions"][0]),
                   prediction_source=saved.get("prediction_source", "predictor"))
        if trained.get("predictor"):
            out["predictor"] = trained["predictor"]
    if "prediction_error" in keys:
        out.update(prediction_calibration=True, calibration_alpha=float(saved.get("calibration_alpha", 0.1)))
    return out
