"""The weight files a policy config loads, and one digest of their bytes for episode fingerprints.

A benchmark or evaluation folder resumes by fingerprint (`envs.runner.fingerprint`). The policy config names
its predictor or agent, but a name is not its weights: retraining `gpgraph-stgcnn-synthetic` or re-packaging
`ppo-crowdnav` keeps the name. The digest of the files behind the names goes into the fingerprint, so records
made with other weights are refused on resume instead of being mixed silently into a new leaderboard.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from envs.plugins import SB3_PREFIX, is_plugin, parse_sb3
from envs.policies import AGENTS_DIR, DEFAULT_PREDICTOR, POLICIES, PREDICTOR_POLICIES, PolicyConfig


def _checkpoint_file(name_or_path: str) -> Path | None:
    """The file a predictor name or path loads (`predictor.checkpoint.resolve`, without importing torch);
    None for plug-ins, constant velocity and names that are not files (loading them fails later, clearly)."""
    import predictor  # the package itself is light: torch loads with its public names' first use

    path = Path(name_or_path)
    if path.is_file():
        return path
    packaged = Path(predictor.__file__).parent / "checkpoints" / f"{name_or_path}.safetensors"
    return packaged if packaged.is_file() else None


def artifact_files(cfg: PolicyConfig) -> list[Path]:
    """The weight files `make_policy(cfg)` loads: the predictor's checkpoint (mpc-gpgraph, plug-in policies
    given a predictor), the packaged agent of a registry agent policy, or the `sb3:` file."""
    files: list[Path | None] = []
    predictor = cfg.predictor if cfg.predictor is not None else \
        DEFAULT_PREDICTOR if cfg.name in PREDICTOR_POLICIES else None
    if predictor is not None and not is_plugin(predictor):
        files.append(_checkpoint_file(predictor))
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
