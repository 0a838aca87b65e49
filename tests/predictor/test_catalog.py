"""`gpgraph list` says what each packaged checkpoint is, from its own metadata (`predictor.catalog`)."""

from __future__ import annotations

import pytest

from envs.config import DEFAULT_PREDICTOR
from predictor.catalog import ROLES, catalog, describe, read_metadata
from predictor.checkpoint import PACKAGE_CHECKPOINTS, read_safetensors
from predictor.cli import main
from predictor.group_rules import split_group_rule

NAMES = sorted(p.stem for p in PACKAGE_CHECKPOINTS.glob("*.safetensors"))


@pytest.mark.parametrize("name", NAMES)
def test_header_metadata_is_what_the_loader_reads(name):
    """The torch-free header reader agrees with the checkpoint loader."""
    info, loaded = read_metadata(PACKAGE_CHECKPOINTS / f"{name}.safetensors"), read_safetensors(
        PACKAGE_CHECKPOINTS / f"{name}.safetensors")
    assert (info["config"], info["meta"], info["format"]) == (loaded["config"], loaded["meta"], loaded["format"])


@pytest.mark.parametrize("name", NAMES)
def test_each_description_states_backbone_data_and_validation_loss(name):
    info = read_metadata(PACKAGE_CHECKPOINTS / f"{name}.safetensors")
    config, meta = info["config"], info["meta"]
    text = describe(name)
    grouped = config["inter_branch"] or config["intra_branch"]
    assert text.startswith(f"GP-Graph-{config['backbone'].upper()}, " if grouped
                           else f"{config['backbone'].upper()} (no group branches)")
    assert grouped == ("assigner" in text)
    assert ("pairwise group assigner" in text) == (config.get("assigner") == "pairwise")
    assert f"trained on {'crowdsim synthetic data' if meta['scene'] == 'synthetic' else 'ETH/UCY'}" in text
    assert meta["scene"] in text
    assert f"val loss {meta['val_loss']:.3f} (epoch {meta['epoch']} of {meta['train']['epochs']} kept)" in text
    assert ("fine-tuned from gpgraph-stgcnn-synthetic" in text) == name.endswith("-pretrained")
    mix = meta.get("interpolation")  # WiSE-FT (predictor.interpolate): the weights' mixture is stated
    assert (mix is not None) == name.endswith("-pretrained")
    if mix:
        assert f"then weights {1 - mix['alpha']:g} x {mix['start']} + {mix['alpha']:g} x the fine-tuned" in text
        assert "the fine-tuned run's val loss" in text


def test_roles_name_the_default_predictor_of_the_env():
    name, rule = split_group_rule(DEFAULT_PREDICTOR)
    assert name in ROLES and "default predictor of mpc-gpgraph" in ROLES[name]
    assert f"grouping by the {rule} rule ({DEFAULT_PREDICTOR})" in ROLES[name]
    assert set(ROLES) <= set(NAMES)


def test_list_prints_one_described_line_per_name(capsys):
    assert main(["list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == [n for n, _ in catalog()] == [*NAMES, "constant-velocity"]
    default = next(ln for ln in lines if ln.split()[0] == split_group_rule(DEFAULT_PREDICTOR)[0])
    assert "GP-Graph-STGCNN, pairwise group assigner; average linkage at 1.1 x the learned threshold" in default
    assert "trained on crowdsim synthetic data (96/24/24 train/val/test recordings)" in default
    assert default.endswith("the default predictor of mpc-gpgraph (and of every crowdnav policy that predicts)")
    assert "model-free baseline" in lines[-1]
    assert len({ln.index(ln.split()[1]) for ln in lines}) == 1  # descriptions start in one column
