"""Stable-baselines3 agent files without unpickling: save with the observation layout, load safely, check layouts.

An SB3 `.zip` holds a JSON "data" entry (some settings as base64 pickles plus readable copies of their fields)
and the weights as `.pth` files. Here nothing pickled is ever loaded:
- settings that would be unpickled are replaced: the spaces by the env's, schedules by constants, and
  `policy_kwargs` rebuilt from its readable fields, with classes only from an allow-list (`ALLOWED_CLASSES`);
- the weights load with `torch.load(weights_only=True)` (SB3's loader);
- agents saved here carry `crowdnav.json` (the env's observation signature, `envs.observation.signature`, and
  training metadata); an agent whose signature differs from the env's is refused with the mismatch named. For
  other SB3 files the keys and shapes are read from the readable copy of the observation space;
- the metadata's `decision_every_steps` (`DECISION_KEY`) is the agent's decision period: it acted every k env
  steps and held its action in between while training (`decision_period`; absent, as in older agents: 1).
- an agent of one of the project's own SB3 subclasses (`LOCAL_ALGOS`, e.g. the constrained `PPOLagrangian`, whose
  weights include a cost critic) names its class in `crowdnav.json` ("algorithm"), and loads as that class when
  it extends the algorithm asked for (`sb3:PATH.zip` asks for PPO).
"""

from __future__ import annotations

import ast
import json
import pickle  # only for its exception class: nothing is unpickled here
import re
import zipfile
from collections import deque
from pathlib import Path
from typing import Any

from envs.atomic import write_atomic
from envs.config import CrowdNavConfig
from envs.observation import mismatches, signature

LAYOUT_ENTRY = "crowdnav.json"
DECISION_KEY = "decision_every_steps"  # in crowdnav.json's "meta": env steps per agent decision
SB3_ALGOS = ("PPO", "A2C", "SAC", "TD3", "DDPG")
# The project's subclasses of SB3 algorithms: class name (recorded in crowdnav.json) -> (module, attribute)
LOCAL_ALGOS = {"PPOLagrangian": ("envs.rl.lagrangian", "PPOLagrangian")}
# Entries SB3 would unpickle that are safe to replace: SB3's default policy for a Dict observation and its
# default buffers (None), constant schedules (only used when training) and no training state.
_SAFE_REPLACEMENTS: dict[str, Any] = {
    "policy_class": None, "rollout_buffer_class": None, "replay_buffer_class": None,
    "lr_schedule": lambda _: 0.0, "learning_rate": 0.0, "clip_range": lambda _: 0.0, "clip_range_vf": None,
    "exploration_schedule": lambda _: 0.0, "_last_obs": None, "_last_episode_starts": None,
    "_last_original_obs": None, "_episode_storage": None,
}
ALLOWED_CLASSES = {  # readable class names in policy_kwargs -> (module, attribute)
    "<class 'envs.rl.extractor.CrowdAttentionExtractor'>": ("envs.rl.extractor", "CrowdAttentionExtractor"),
    # agents saved before envs/ became four rooms (the packaged ppo-crowdnav among them) name its old module
    "<class 'envs.extractor.CrowdAttentionExtractor'>": ("envs.rl.extractor", "CrowdAttentionExtractor"),
    **{f"<class 'torch.nn.modules.activation.{n}'>": ("torch.nn", n) for n in ("ReLU", "Tanh", "ELU", "GELU", "SiLU")},
    "<class 'torch.optim.adam.Adam'>": ("torch.optim", "Adam"),
}
# What a damaged file raises inside SB3/torch loading (weights_only refusals are UnpicklingError).
LOAD_ERRORS = (ValueError, RuntimeError, KeyError, TypeError, EOFError, OSError, zipfile.BadZipFile,
               pickle.UnpicklingError)
_BOX_RE = re.compile(r"'(\w+)': Box\([^()]*?\((\d+(?:, \d+)*),?\), \w+\)")


def read_agent(path: Path) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """The JSON "data" entry of an SB3 file and its `crowdnav.json` entry (signature and metadata; None for
    agents not saved here), in one read; ValueError when the file is not an SB3 model."""
    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
            layout = json.loads(z.read(LAYOUT_ENTRY)) if LAYOUT_ENTRY in names else None
            return json.loads(z.read("data")), layout
    except (OSError, zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a stable-baselines3 model file ({exc})") from exc


def decision_period(layout: dict[str, Any] | None) -> int:
    """Env steps per decision of an agent from its `crowdnav.json` entry (`read_agent`); 1 when not recorded.
    ValueError when the recorded value is not an integer >= 1."""
    value = ((layout or {}).get("meta") or {}).get(DECISION_KEY, 1)
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise ValueError(f"{DECISION_KEY} must be an integer >= 1, got {value!r}")
    return value


def _class(name: str) -> Any:
    import importlib

    if name not in ALLOWED_CLASSES:
        raise ValueError(f"class {name} is not on the allow-list of loadable classes")
    module, attr = ALLOWED_CLASSES[name]
    return getattr(importlib.import_module(module), attr)


def _policy_kwargs(entry: dict[str, Any]) -> dict[str, Any]:
    """policy_kwargs rebuilt from the readable fields of its pickled entry (classes from the allow-list)."""
    out: dict[str, Any] = {}
    for key, value in entry.items():
        if key.startswith(":"):
            continue
        if isinstance(value, str) and value.startswith("<class '"):
            out[key] = _class(value)
        elif isinstance(value, str) and key in ("net_arch", "features_extractor_kwargs", "optimizer_kwargs"):
            out[key] = ast.literal_eval(value)  # a literal that JSON could not hold (e.g. a tuple)
        else:
            out[key] = value
    return out


def custom_objects(data: dict[str, Any], path: Path) -> dict[str, Any]:
    """Replacements for every pickled entry of `data`; ValueError when one cannot be replaced safely."""
    pickled = sorted(k for k, v in data.items() if isinstance(v, dict) and ":serialized:" in v)
    fresh = {"ep_info_buffer": deque(maxlen=100), "ep_success_buffer": deque(maxlen=100)}  # logging only
    out = {k: _SAFE_REPLACEMENTS[k] if k in _SAFE_REPLACEMENTS else fresh[k] for k in pickled
           if k in _SAFE_REPLACEMENTS or k in fresh}
    unsafe = [k for k in pickled if k not in out and k not in ("observation_space", "action_space", "policy_kwargs")]
    if unsafe:
        raise ValueError(f"{path}: settings {unsafe} would need unpickling Python objects; refusing to load")
    if "policy_kwargs" in pickled:
        try:
            out["policy_kwargs"] = _policy_kwargs(data["policy_kwargs"])
        except (ValueError, SyntaxError) as exc:
            raise ValueError(f"{path}: policy_kwargs cannot be rebuilt without unpickling ({exc})") from exc
    return out


def saved_signature(data: dict[str, Any], layout: dict[str, Any] | None) -> dict[str, Any] | None:
    """The observation signature of an SB3 file: its `crowdnav.json`, else keys/shapes parsed from the readable
    copy of its observation space (None when neither is there)."""
    if layout is not None:
        return layout["signature"]
    spaces_text = data.get("observation_space", {}).get("spaces")
    if not isinstance(spaces_text, str):
        return None
    keys = {m.group(1): [int(x) for x in m.group(2).split(",")] for m in _BOX_RE.finditer(spaces_text)}
    return {"keys": keys} if keys else None


GROWABLE_KEYS = ("predictions", "prediction_error", "prediction_error_count")  # inputs a run may add to an agent


def check_layout(path: Path, config: CrowdNavConfig, growable: bool = False
                 ) -> tuple[dict[str, Any], dict[str, Any] | None, list[str]]:
    """The "data" and `crowdnav.json` entries of the agent in `path` (`read_agent`) and, with `growable`, the
    prediction inputs this env observes and the agent did not (`GROWABLE_KEYS`; else []); ValueError naming every
    other difference between the agent's observation and this env's."""
    data, layout = read_agent(path)
    saved, current = saved_signature(data, layout), signature(config)
    added = [k for k in GROWABLE_KEYS if k in current["keys"] and k not in saved["keys"]] if growable and saved else []
    reduced = dict(current, keys={k: v for k, v in current["keys"].items() if k not in added})
    diff = [] if saved is None else mismatches(saved, reduced)
    if diff:
        raise ValueError(f"{path}: the agent was trained on another observation layout: {'; '.join(diff)}")
    return data, layout, added


def agent_class(algo: str, layout: dict[str, Any] | None) -> Any:
    """The class to load an agent as: SB3's `algo`, or the project's subclass of it that the agent's
    `crowdnav.json` names (`LOCAL_ALGOS`); ValueError for a class not on that list or not extending `algo`."""
    import importlib

    import stable_baselines3

    base = getattr(stable_baselines3, algo)
    name = (layout or {}).get("algorithm")
    if name is None or name == algo:
        return base
    if name not in LOCAL_ALGOS:
        raise ValueError(f"algorithm {name!r} is not on the allow-list of loadable classes "
                         f"({', '.join([*SB3_ALGOS, *LOCAL_ALGOS])})")
    module, attr = LOCAL_ALGOS[name]
    cls = getattr(importlib.import_module(module), attr)
    if not issubclass(cls, base):
        raise ValueError(f"the agent is a {name}, which is not a kind of {algo}")
    return cls


def load_agent(path: Path, algo: str, env: Any, extra_ok: bool = False) -> Any:
    """The SB3 model in `path` for this env (its spaces), loaded without unpickling; ValueError otherwise. With
    `extra_ok` the env may observe predictions the agent was not trained on (`GROWABLE_KEYS`): the model's
    observation space is then the env's without them, and its user passes it only its own keys."""
    from gymnasium import spaces

    if not path.is_file():
        raise ValueError(f"no such file {path}")
    data, layout, extra = check_layout(path, env.config, growable=extra_ok)
    custom = custom_objects(data, path)
    try:
        cls = agent_class(algo, layout)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc
    space = spaces.Dict({k: v for k, v in env.observation_space.spaces.items() if k not in extra})
    custom.update(observation_space=space, action_space=env.action_space,
                  policy_class=cls.policy_aliases["MultiInputPolicy"])
    try:
        return cls.load(path, custom_objects=custom, device="cpu")
    except LOAD_ERRORS as exc:
        raise ValueError(f"{path}: cannot load as {cls.__name__} for this env ({str(exc).splitlines()[0]})") from exc


def load_parameters(model: Any, path: Path, config: CrowdNavConfig) -> None:
    """Weights (and optimiser state) of `path` into `model` (weights_only); ValueError on a layout mismatch."""
    check_layout(path, config)
    try:
        model.set_parameters(str(path), exact_match=True, device="cpu")
    except LOAD_ERRORS as exc:
        raise ValueError(f"{path}: cannot load its weights ({str(exc).splitlines()[0]})") from exc


GROWN_WEIGHT = "row_enc.0.weight"  # the extractor's first layer over a pedestrian's row (`CrowdAttentionExtractor`)


def _grow(params: dict[str, Any], own: dict[str, Any]) -> list[str]:
    """Widen, in place, each saved first row layer (`GROWN_WEIGHT`) to `own`'s wider one: the saved columns first,
    the new inputs' columns (the extractor appends them to each row) zero, so the policy computes what the agent
    did. Returns the widened names; ValueError for any other shape that differs."""
    grown = []
    for name, value in params.items():
        want = own.get(name)
        if want is None or want.shape == value.shape:
            continue
        if not (name.endswith(GROWN_WEIGHT) and want.shape[0] == value.shape[0] and want.shape[1] > value.shape[1]):
            raise ValueError(f"{name} has shape {tuple(value.shape)}, this run's {tuple(want.shape)}")
        wide = value.new_zeros(want.shape)  # a tensor's own method: torch is not imported here
        wide[:, :value.shape[1]] = value
        params[name] = wide
        grown.append(name)
    return grown


def load_policy_weights(model: Any, path: Path, config: CrowdNavConfig, every: int,
                        any_period: bool = False) -> list[str]:
    """The policy weights of the agent in `path` into `model`'s policy (`weights_only`), to start training from them;
    the optimiser starts afresh. The observation layout and the decision period `every` must be the agent's (the
    period need not with `any_period`: a warm start re-fits the policy to the run's period), and every
    saved weight must fit; weights `model` has and the agent lacks (a constrained PPO's cost critic) keep their
    initial values and are returned by name. The run may observe predictions the agent did not (`GROWABLE_KEYS`):
    the network grows, its new inputs entering with zero weight (their encoders initial, returned by name, with the
    widened layers), so it starts as the agent. ValueError otherwise."""
    from stable_baselines3.common.save_util import load_from_zip_file

    _, layout, added = check_layout(path, config, growable=True)
    if not any_period and decision_period(layout) != every:
        raise ValueError(f"{path}: the agent decides every {decision_period(layout)} env steps, this run every {every}")
    try:  # SB3's reader: torch.load(weights_only=True) of each .pth entry, the "data" entry not read
        _, params, _ = load_from_zip_file(path, load_data=False, device="cpu")
        grown = _grow(params["policy"], model.policy.state_dict()) if added else []
        missing, unexpected = model.policy.load_state_dict(params["policy"], strict=False)
    except LOAD_ERRORS as exc:
        raise ValueError(f"{path}: cannot load its policy weights ({str(exc).splitlines()[0]})") from exc
    encoders = ("pred_enc.", "calib_enc.") if added else ()  # the new inputs' encoders start as initialised
    foreign = [k for k in missing if not k.startswith("cost_net.")
               and not k.split("features_extractor.")[-1].startswith(encoders)]
    if unexpected or foreign:
        raise ValueError(f"{path}: its policy does not fit this run's (missing {foreign}, unexpected {unexpected})")
    return list(missing) + grown


def save_agent(model: Any, path: Path, config: CrowdNavConfig, meta: dict[str, Any] | None = None) -> None:
    """Save atomically (a reader sees the old file or the complete new one) with `crowdnav.json` inside."""
    layout: dict[str, Any] = {"signature": signature(config), "meta": meta or {}}
    if type(model).__name__ in LOCAL_ALGOS:  # loaded as that class (`agent_class`); SB3's own need no entry
        layout["algorithm"] = type(model).__name__

    def write(tmp: str) -> None:
        model.save(tmp)
        with zipfile.ZipFile(tmp, "a") as z:
            z.writestr(LAYOUT_ENTRY, json.dumps(layout, indent=1))

    write_atomic(Path(path), write)
