"""The one ETH/UCY reader (predictor.ethucy): one policy for every package, and a fuzz test of malformed files."""

from __future__ import annotations

import os
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from predictor.ethucy import DEFAULT_DATA_DIR, DataFormatError, read_groups, read_labels, read_trajectories

ROWS = np.array([[10.0 * (i // 3), i % 3 + 1, 0.5 * i, -0.25 * i] for i in range(30)])


def _text(rows: np.ndarray, sep: str = "\t") -> str:
    return "".join(sep.join(f"{v:.2f}" if j >= 2 else f"{v:.1f}" for j, v in enumerate(r)) + "\n" for r in rows)


def _write(tmp_path: Path, data: str | bytes, name: str = "f.txt") -> Path:
    path = tmp_path / name
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    return path


def test_every_package_reads_with_this_reader():
    import envs.crowds.replay
    import predictor.data

    assert envs.crowds.replay.read_trajectories is read_trajectories and envs.crowds.replay.read_groups is read_groups
    assert predictor.data.DataFormatError is DataFormatError


def test_a_real_benchmark_file_reads(tmp_path):
    path = DEFAULT_DATA_DIR / "hotel" / "test" / "biwi_hotel.txt"
    if not path.is_file():
        pytest.skip(f"{DEFAULT_DATA_DIR} is not here")
    rows = read_trajectories(path)
    assert rows.shape[1] == 4 and len(rows) > 1000 and np.all(rows[:, :2] == np.round(rows[:, :2]))


@pytest.mark.parametrize("text, what", [
    ("1 2 3.7\n", "whole number"),          # was silently cut to 3 by two of the old readers
    ("1 2\n2 3\n", "already listed"),
    ("1 2 1\n", "already listed"),
    ("1 nan\n", "non-finite"),
    ("1 1e300\n", "whole number"),
    ("1, 2\n", "non-numeric"),
])
def test_group_file_policy(tmp_path, text, what):
    with pytest.raises(DataFormatError, match=rf"g\.txt:\d+: .*{what}"):
        read_groups(_write(tmp_path, text, "g.txt"))


def test_groups_labels_and_empty_group_files(tmp_path):
    assert read_groups(_write(tmp_path, "3 4\n\n 7\t8  9 \n", "g.txt")) == ((3, 4), (7, 8, 9))
    assert read_groups(_write(tmp_path, "\n", "e.txt")) == ()  # a crowd of singles
    labels = read_labels(_write(tmp_path, "0 1 0\n0 2 0\n10 1 1\n", "l.tsv"))
    assert labels.shape == (3, 3)
    with pytest.raises(DataFormatError, match="whole number"):
        read_labels(_write(tmp_path, "0 1 0.5\n", "l2.tsv"))


SAME = ("tabs_and_spaces", "blank_lines", "crlf")  # mutations that keep the content: the read must be unchanged
BROKEN = ("drop_field", "extra_field", "comma", "nan", "inf", "huge_id", "fractional_id", "duplicate_row",
          "random_bytes", "nul_byte", "latin1", "empty")


def _mutate(kind: str, rng: np.random.Generator) -> str | bytes:
    lines = _text(ROWS).splitlines()
    i = int(rng.integers(len(lines)))
    parts = lines[i].split("\t")
    if kind == "tabs_and_spaces":
        return "".join(rng.choice(["\t", " ", "   ", " \t "]).join(line.split("\t")) + "\n" for line in lines)
    if kind == "blank_lines":
        return "\n".join(line + ("\n  \t" if k == i else "") for k, line in enumerate(lines)) + "\n\n"
    if kind == "crlf":
        return "\r\n".join(lines) + "\r\n"
    if kind in ("drop_field", "extra_field", "comma"):
        parts = {"drop_field": parts[:-1], "extra_field": [*parts, "1.0"], "comma": [",".join(parts)]}[kind]
    elif kind in ("nan", "inf"):
        parts[int(rng.integers(4))] = str(rng.choice(["nan", "NaN", "inf", "-inf", "Infinity"]))
    elif kind == "huge_id":
        parts[int(rng.integers(2))] = str(rng.choice(["1e20", "9007199254740993", "-1e300"]))
    elif kind == "fractional_id":
        parts[int(rng.integers(2))] = str(rng.choice(["2.5", "0.1", "7.000001"]))
    elif kind == "duplicate_row":
        lines.insert(int(rng.integers(len(lines) + 1)), lines[i])
    elif kind == "random_bytes":
        return rng.integers(0, 256, int(rng.integers(1, 400)), dtype=np.uint8).tobytes()
    elif kind == "nul_byte":
        return ("\n".join(lines[:i]) + "\n\x00" + "\n".join(lines[i:]) + "\n").encode()
    elif kind == "latin1":
        return ("\n".join(lines) + "\n10 1 1.0 2.0 \xe9\n").encode("latin-1")
    elif kind == "empty":
        return rng.choice(["", "\n", "  \n\t\n"])
    lines[i] = "\t".join(parts)
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("kind", SAME + BROKEN)
def test_fuzz_malformed_files_give_a_clean_error_and_valid_variants_read_the_same(tmp_path, kind):
    rng = np.random.default_rng(zlib.crc32(kind.encode()))  # deterministic per kind
    expected = read_trajectories(_write(tmp_path, _text(ROWS), "ref.txt"))
    np.testing.assert_array_equal(expected, np.round(ROWS, 2))
    for trial in range(25):
        path = _write(tmp_path, _mutate(kind, rng), f"m{trial}.txt")
        if kind in SAME:
            np.testing.assert_array_equal(read_trajectories(path), expected)
        else:
            with pytest.raises(DataFormatError, match=rf"m{trial}\.txt"):
                read_trajectories(path)


def test_fuzz_truncated_files_never_crash_and_keep_every_complete_row(tmp_path):
    data = _text(ROWS).encode()
    rng = np.random.default_rng(11)
    for trial, cut in enumerate(rng.integers(1, len(data), 60)):
        path = _write(tmp_path, data[:cut], f"t{trial}.txt")
        complete = data[:cut].count(b"\n")
        try:
            rows = read_trajectories(path)
        except DataFormatError:
            continue
        # A cut inside the last number may still parse (the text as given); every earlier row is intact.
        np.testing.assert_array_equal(rows[:complete], np.round(ROWS, 2)[:complete])
        assert len(rows) in (complete, complete + 1)


def test_data_dir_has_one_owner_and_an_environment_override(tmp_path):
    from envs.evaluation.suite import DEFAULT_DATA

    assert DEFAULT_DATA is DEFAULT_DATA_DIR
    env = {k: v for k, v in os.environ.items() if k != "ETH_UCY_DIR"}
    code = "from envs.evaluation.suite import DEFAULT_DATA; print(DEFAULT_DATA)"
    for override, expected in ((None, "../shared/datasets/eth_ucy"), (str(tmp_path / "x"), str(tmp_path / "x"))):
        run_env = env if override is None else {**env, "ETH_UCY_DIR": override}
        out = subprocess.run([sys.executable, "-c", code], env=run_env, capture_output=True, text=True, check=True)
        assert out.stdout.strip() == expected


def test_overlapping_groups_are_refused_or_merged_with_a_warning_naming_the_lines(tmp_path):
    from predictor.ethucy import GroupFileWarning

    path = _write(tmp_path, "1 2\n3 4\n2 5\n6\n6 7\n8 8\n", "g.txt")
    with pytest.raises(DataFormatError, match=r"g\.txt:3: pedestrian 2 is already listed \(line 1\).*merge"):
        read_groups(path)
    with pytest.warns(GroupFileWarning) as caught:
        merged = read_groups(path, overlaps="merge")
    assert merged == ((1, 2, 5), (3, 4), (6, 7), (8,))  # in the place of the first line, members once each
    assert [str(w.message).split(": ", 1)[1] for w in caught] == [
        "pedestrian 2 is listed on lines 1 and 3: their groups are merged into one",
        "pedestrian 6 is listed on lines 4 and 5: their groups are merged into one",
        "pedestrian 8 is listed on lines 6 and 6: their groups are merged into one"]
    chain = _write(tmp_path, "1 2\n3 4\n5 6\n4 6 2\n", "c.txt")  # one line joins three earlier groups
    with pytest.warns(GroupFileWarning):
        assert read_groups(chain, overlaps="merge") == ((1, 2, 3, 4, 5, 6),)
    with pytest.raises(ValueError, match="valid: error, merge"):
        read_groups(path, overlaps="ignore")


def test_the_published_students003_groups_merge_as_their_readme_says():
    from predictor.ethucy import GroupFileWarning

    path = DEFAULT_DATA_DIR.parent / "eth_ucy_groups" / "students003.groups.txt"
    if not path.is_file():
        pytest.skip(f"{path} is not here")
    with pytest.raises(DataFormatError, match="already listed"):
        read_groups(path)
    with pytest.warns(GroupFileWarning) as caught:
        groups = read_groups(path, overlaps="merge")
    named = sorted(int(str(w.message).split("pedestrian ")[1].split()[0]) for w in caught)
    assert named == [103, 121, 421, 422] and len(groups) == 104 - 3  # three pairs of lines become one group each
    members = [p for g in groups for p in g]
    assert len(members) == len(set(members))  # nobody in two groups after the merge
