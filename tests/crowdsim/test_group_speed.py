"""Walking speed by group size and the grouped share in a scenario crowd (issue 50, item 3;
scripts/measure_group_speed.py).

An independent check of one 300 s plaza run (24 people) found 1.22 / 1.22 / 1.18 / 1.27 / 1.14 m/s for groups of
1-5: no fall with size. Each group draws its desired speed from N(1.34 - 0.02 (n - 1), 0.26) m/s, so one run's few
groups of 4-5 scatter by ~0.1 m/s; over 10 seeds x 600 s (seeds 2000-2009) the plaza gives 1.253 / 1.204 / 1.170 /
1.103 / 1.028 m/s (1.239 / 1.194 / 1.159 / 1.103 / 1.094 before people walked round corners, `crowdsim.detour`).
The test measures the fall with that draw replaced by its expectation (`GroupWalks.relative_by_size`), on its own
seeds.
"""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.config import GroupConfig, SimConfig
from crowdsim.walking import group_walks

SEEDS = range(10, 26)  # the measurements in the docs used 2000-2009
STEPS = 1000  # 400 s per seed


@pytest.fixture(scope="module")
def script(load_script):
    return load_script("measure_group_speed")


@pytest.fixture(scope="module")
def plaza():
    return group_walks(SimConfig(scenario="plaza", n_pedestrians=24), SEEDS, STEPS)


def test_bootstrap_interval_holds_the_mean_and_has_the_normal_width(script):
    values = np.random.default_rng(1).normal(1.2, 0.2, 400)
    mean, lo, hi = script.bootstrap_mean(values, np.random.default_rng(0))
    assert lo < mean < hi and mean == pytest.approx(values.mean())
    assert hi - lo == pytest.approx(2 * 1.96 * values.std() / np.sqrt(len(values)), rel=0.15)
    assert np.isnan(script.bootstrap_mean(values[:1], np.random.default_rng(0))[1])


def test_window_shares_average_runs_and_steps_per_window(script):
    share = np.array([[0.5, 0.7, 0.6, 0.6, 1.0], [0.7, 0.5, 0.8, 0.8, 0.0]])
    np.testing.assert_allclose(script.window_shares(share, 2), [0.6, 0.7])  # the incomplete window is dropped


def test_a_crowd_of_singles_has_no_groups_and_a_grouped_share_of_zero():
    walks = group_walks(SimConfig(scenario="plaza", n_pedestrians=6, groups=GroupConfig(size_poisson_rate=0.0)),
                        [0], 60)
    assert set(walks.size.tolist()) == {1} and len(walks.speed) >= 6
    assert np.all(walks.share == 0.0)
    assert np.all((walks.speed > 0.5) & (walks.speed < 2.0))


def test_speed_falls_with_group_size_in_the_plaza_crowd(plaza):
    """1 > 3 > 5 with 95 % bootstrap intervals over groups that do not overlap (seeds 10-25, 400 s each)."""
    drop = GroupConfig().speed_drop_per_member_mps
    rng = np.random.default_rng(0)
    alone = plaza.relative_by_size(1, drop).mean()
    intervals = {}
    for n in (1, 3, 5):
        rel = plaza.relative_by_size(n, drop) - alone
        assert len(rel) >= 20, (n, len(rel))
        means = rel[rng.integers(0, len(rel), (2000, len(rel)))].mean(axis=1)
        intervals[n] = np.percentile(means, [2.5, 97.5])
    assert intervals[3][1] < intervals[1][0] and intervals[5][1] < intervals[3][0], intervals


def test_groups_walk_no_faster_than_their_desired_speed_on_average(plaza):
    """The catch-up term speeds up a member who has fallen behind, but it must not carry a group faster than it
    wants to walk: per size, the mean walked speed stays below the mean desired speed."""
    for n in range(2, 6):
        chosen = plaza.size == n
        assert chosen.any()
        assert plaza.speed[chosen].mean() < plaza.desired[chosen].mean(), n


def test_grouped_share_stays_near_two_thirds_in_every_time_window(script, plaza):
    """Zero-truncated Poisson sizes at rate 1.1 put 0.667 of people in groups; the inflow corrects arrivals for
    how long each size stays (`groups.draw_inflow_size`), so the share holds over the run."""
    windows = script.window_shares(plaza.share, 125)  # 50 s windows, each the mean over the seeds
    assert len(windows) == 8
    assert np.all((windows >= 0.6) & (windows <= 0.74)), windows.round(3)
    assert abs(np.nanmean(plaza.share) - 0.667) < 0.03


def test_small_mode_prints_a_table_for_each_size(script, capsys):
    assert script.main(["--small"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("## plaza") and "grouped share: mean" in out
    assert [line.split("|")[0].strip() for line in out.splitlines()[2:7]] == ["1", "2", "3", "4", "5"]


@pytest.mark.parametrize("argv", [["--seeds", "x"], ["--seeds", "5-3"], ["--set", "groups.nope=1"],
                                  ["--people", "0"], ["--duration-s", "0"]])
def test_bad_input_is_one_line_on_stderr_and_exit_2(script, capsys, argv):
    assert script.main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1
