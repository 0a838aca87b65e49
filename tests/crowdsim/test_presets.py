"""Domain randomisation presets: deterministic per recording, within their ranges, recorded in the metadata."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from crowdsim.generate import RunSpec, dataset_jobs, make_dataset
from crowdsim.presets import PRESETS, REALISTIC_V1, Randomization, get_preset, sample_config
from crowdsim.sim import CrowdSimulator


def test_a_recordings_config_depends_only_on_preset_scenario_and_seed():
    assert sample_config(REALISTIC_V1, "plaza", 7) == sample_config(REALISTIC_V1, "plaza", 7)
    jobs_a = dataset_jobs(["plaza", "corridor"], 4, None, RunSpec(seed=5), preset="realistic-v1")
    jobs_b = dataset_jobs(["corridor"], 6, None, RunSpec(seed=3), preset="realistic-v1")
    a = {(j.config.scenario, j.spec.seed): j.config for j in jobs_a}
    b = {(j.config.scenario, j.spec.seed): j.config for j in jobs_b}
    assert all(a[k] == b[k] for k in a.keys() & b.keys()) and len(a.keys() & b.keys()) == 4
    # other versions of the preset draw other configs
    bumped = replace(REALISTIC_V1, version=2)
    assert sample_config(bumped, "plaza", 7) != sample_config(REALISTIC_V1, "plaza", 7)


def test_draws_cover_their_ranges_and_stay_inside_them():
    r = REALISTIC_V1.randomization
    configs = [sample_config(REALISTIC_V1, "plaza", seed) for seed in range(200)]
    for values, (lo, hi) in (
        ([c.n_pedestrians for c in configs], r.pedestrians["plaza"]),
        ([c.social.desired_speed_mean_mps for c in configs], r.desired_speed_mean_mps),
        ([c.groups.size_poisson_rate for c in configs], r.size_poisson_rate),
        ([c.behaviour.stop_rate_hz for c in configs], r.stop_rate_hz),
        ([c.behaviour.stranger_companion_prob for c in configs], r.stranger_companion_prob),
        ([dict(c.scenario_options)["size_m"] for c in configs], r.scenario_options["plaza"]["size_m"]),
    ):
        values = np.asarray(values)
        assert values.min() >= lo and values.max() <= hi
        assert values.max() - values.min() > 0.8 * (hi - lo)  # the range is actually explored


def test_unknown_names_and_bad_ranges_are_errors():
    with pytest.raises(ValueError, match="valid names: realistic-v1"):
        get_preset("realistic")
    with pytest.raises(ValueError, match="its scenarios"):
        sample_config(REALISTIC_V1, "open", 0)
    with pytest.raises(ValueError, match="lo <= hi"):
        Randomization(pedestrians={"plaza": (10, 5)})
    assert set(PRESETS) == {"realistic-v1"}


@pytest.mark.parametrize("scenario", REALISTIC_V1.scenarios)
def test_every_scenario_of_the_preset_runs_at_its_extremes(scenario):
    r = REALISTIC_V1.randomization
    for seed in range(6):
        config = sample_config(REALISTIC_V1, scenario, seed)
        config = replace(config, n_pedestrians=r.pedestrians[scenario][1 if seed % 2 else 0])
        sim = CrowdSimulator(config)
        sim.reset(seed)
        for _ in range(20):
            state = sim.step()
        assert np.all(np.isfinite(state.pos[state.active]))


def test_dataset_with_a_preset_records_the_drawn_config(tmp_path):
    out = make_dataset(tmp_path, ["corridor", "plaza"], 3, None, RunSpec(duration_s=4.0, warmup_s=0.0, seed=11),
                       progress=False, preset="realistic-v1")
    metas = [json.loads(p.with_suffix(".json").read_text()) for split in out.values() for p in split]
    assert len(metas) == 6 and all(m["preset"] == "realistic-v1@1" for m in metas)
    for m in metas:
        drawn = sample_config(REALISTIC_V1, m["scenario"], m["seed"])
        assert m["config"]["n_pedestrians"] == drawn.n_pedestrians
        assert m["config"]["behaviour"]["stop_rate_hz"] == drawn.behaviour.stop_rate_hz
    assert len({m["config"]["groups"]["size_poisson_rate"] for m in metas}) == 6
