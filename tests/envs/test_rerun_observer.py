"""`envs.drawing.rerun_observer.RerunObserver`: an episode written to .rrd, read back with `rerun.chunk.RrdReader`."""

from __future__ import annotations

import importlib
import sys
from collections import defaultdict

import numpy as np
import pytest

from crowdsim.recording import palette
from envs.drawing.frame import SceneFrame

N_STEPS, K, T = 10, 3, 4
GROUPS = np.array([0, 0, 1, 2, 2, 2])
PLAN_STEPS = 6  # the plan is present on steps 0..5 only


def _episode() -> list[SceneFrame]:
    rng = np.random.default_rng(3)
    frames = []
    for t in range(N_STEPS):
        pos = rng.uniform(0.0, 10.0, (len(GROUPS), 2))
        frames.append(SceneFrame(
            step=t, time_s=0.25 * t, robot_state=np.array([1.0 + 0.1 * t, 2.0, 0.3, 0.5, 0.0]), robot_radius_m=0.3,
            goal=np.array([9.0, 9.0]), ped_pos=pos, ped_vel=np.zeros_like(pos), ped_radius=np.full(len(pos), 0.25),
            group_id=GROUPS, ped_id=np.arange(len(pos)) + 100, walls=np.array([[[0.0, 0.0], [10.0, 0.0]]]),
            bounds=(0.0, 0.0, 10.0, 10.0),
            plan=np.stack([np.linspace(1, 9, 5), np.linspace(2, 9, 5)], axis=1) + t if t < PLAN_STEPS else None,
            predictions=pos + rng.normal(0.0, 1.0, (K, T, len(pos), 2)),
            predicted_group_id=np.array([0, 0, 1, 1, 2, 2]),
            scalars={"reward": 0.5 * t, "min dist": 10.0 - t},
            options=np.stack([np.linspace(1, 9, 5), np.linspace(3, 9, 5)], axis=1)[None] + t if t < 2 else None,
        ))
    return frames


def _read(path) -> dict[str, dict[str, list]]:
    """{entity path: {column: values over the rows of all its chunks, in step order}}."""
    rrd = pytest.importorskip("rerun.chunk")
    raw: dict[str, list[dict]] = defaultdict(list)
    for chunk in rrd.RrdReader(path).stream():
        batch = chunk.to_record_batch()
        cols = {n: batch.column(n).to_pylist() for n in batch.schema.names if n not in ("log_time",)}
        for i in range(chunk.num_rows):
            raw[str(chunk.entity_path)].append({n: v[i] for n, v in cols.items()})
    out: dict[str, dict[str, list]] = {}
    for entity, rows in raw.items():
        rows.sort(key=lambda r: r.get("step", -1))
        out[entity] = {n: [r.get(n) for r in rows] for n in set().union(*rows)}
    return out


def _flip(xy) -> np.ndarray:
    return np.asarray(xy, dtype=np.float32) * np.array([1.0, -1.0], dtype=np.float32)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    pytest.importorskip("rerun")
    from envs.drawing.rerun_observer import RerunObserver

    path = tmp_path_factory.mktemp("rrd") / "out" / "episode.rrd"
    frames = _episode()
    with RerunObserver(path) as obs:
        for frame in frames:
            obs.log(frame)
        assert not path.exists()  # written to a temporary name until close
    assert path.exists() and [p.name for p in path.parent.iterdir()] == ["episode.rrd"]
    return frames, _read(path)


def test_one_row_per_step_on_both_timelines(recorded):
    frames, data = recorded
    peds = data["/world/pedestrians"]
    assert peds["step"] == list(range(N_STEPS))
    assert [d.total_seconds() for d in peds["sim_time"]] == pytest.approx([f.time_s for f in frames])
    assert data["/world/robot"]["step"] == list(range(N_STEPS))


def test_pedestrian_positions_radii_and_group_class_ids_round_trip(recorded):
    frames, data = recorded
    peds = data["/world/pedestrians"]
    for frame, positions, class_ids, radii in zip(frames, peds["Points2D:positions"], peds["Points2D:class_ids"],
                                                  peds["Points2D:radii"], strict=True):
        np.testing.assert_array_equal(np.array(positions, dtype=np.float32), _flip(frame.ped_pos))
        assert class_ids == GROUPS.tolist()
        np.testing.assert_allclose(radii, frame.ped_radius, rtol=1e-6)


def test_annotation_context_gives_each_group_its_palette_colour(recorded):
    _, data = recorded
    ((context,),) = data["/world"]["AnnotationContext:context"]  # one row holding one context
    colours = {c["class_id"]: c["class_description"]["info"]["color"] for c in context}
    for k, (r, g, b) in enumerate(palette()[:3]):
        assert colours[k] == (int(r) << 24) | (int(g) << 16) | (int(b) << 8) | 0xFF


def test_static_walls(recorded):
    _, data = recorded
    (strips,) = data["/world/walls"]["LineStrips2D:strips"]
    np.testing.assert_array_equal(np.array(strips, dtype=np.float32), _flip([[[0.0, 0.0], [10.0, 0.0]]]))
    assert "step" not in data["/world/walls"]


def test_robot_and_goal(recorded):
    frames, data = recorded
    robot = data["/world/robot"]
    for frame, (position,) in zip(frames, robot["Points2D:positions"], strict=True):
        np.testing.assert_array_equal(np.array(position, dtype=np.float32), _flip(frame.robot_pos))
    assert robot["Points2D:radii"][0] == pytest.approx([0.3])
    assert len(data["/world/goal"]["step"]) == N_STEPS
    assert len(data["/world/robot/heading"]["step"]) == N_STEPS


def test_scalars_are_logged_per_step(recorded):
    frames, data = recorded
    assert [v for (v,) in data["/metrics/reward"]["Scalars:scalars"]] == [f.scalars["reward"] for f in frames]
    min_dist = next(v for k, v in data.items() if k.startswith("/metrics/min"))
    assert [v for (v,) in min_dist["Scalars:scalars"]] == [f.scalars["min dist"] for f in frames]


def test_plan_is_logged_while_present_then_cleared_once(recorded):
    frames, data = recorded
    plan = data["/world/plan"]
    logged = [s for s in plan["LineStrips2D:strips"] if s is not None]
    assert len(logged) == PLAN_STEPS
    for frame, (strip,) in zip(frames, logged, strict=False):
        np.testing.assert_array_equal(np.array(strip, dtype=np.float32), _flip(frame.plan))
    clears = [step for step, c in zip(plan["step"], plan.get("Clear:is_recursive", []), strict=True) if c is not None]
    assert clears == [PLAN_STEPS]


def test_passing_options_are_logged_while_present(recorded):
    frames, data = recorded
    opts = data["/world/options"]
    logged = [s for s in opts["LineStrips2D:strips"] if s is not None]
    assert len(logged) == 2
    for frame, (strip,) in zip(frames, logged, strict=False):
        np.testing.assert_array_equal(np.array(strip, dtype=np.float32), _flip(frame.options[0]))


def test_prediction_strips_one_per_sample_and_pedestrian(recorded):
    frames, data = recorded
    pred = data["/world/predictions"]
    assert len(pred["step"]) == N_STEPS
    n = len(GROUPS)
    for frame, strips, class_ids in zip(frames, pred["LineStrips2D:strips"], pred["LineStrips2D:class_ids"],
                                        strict=True):
        assert len(strips) == K * n and class_ids == np.tile(GROUPS, K).tolist()
        for k in range(K):
            for i in range(n):
                expected = np.vstack([frame.ped_pos[i], frame.predictions[k, :, i]])
                np.testing.assert_array_equal(np.array(strips[k * n + i], dtype=np.float32), _flip(expected))
    assert len(data["/world/predicted_groups"]["step"]) == N_STEPS
    assert len(data["/world/groups"]["step"]) == N_STEPS


def test_optional_data_absent_means_no_entity(tmp_path):
    pytest.importorskip("rerun")
    from envs.drawing.rerun_observer import RerunObserver

    frame = _episode()[PLAN_STEPS]  # no plan
    frame = SceneFrame(**{**frame.__dict__, "predictions": None, "predicted_group_id": None, "scalars": {}})
    with RerunObserver(tmp_path / "bare.rrd") as obs:
        obs.log(frame)
    data = _read(tmp_path / "bare.rrd")
    assert "/world/pedestrians" in data
    assert not {"/world/plan", "/world/predictions", "/world/predicted_groups"} & set(data)
    assert not [k for k in data if k.startswith("/metrics")]


def test_non_finite_robot_state_raises(tmp_path):
    pytest.importorskip("rerun")
    from envs.drawing.rerun_observer import RerunObserver

    frame = _episode()[0]
    bad = SceneFrame(**{**frame.__dict__, "robot_state": np.array([np.nan, 0.0, 0.0, 0.0, 0.0])})
    with RerunObserver(tmp_path / "bad.rrd") as obs, pytest.raises(ValueError, match="robot_state"):
        obs.log(bad)


def test_module_imports_without_rerun(monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)  # makes `import rerun` fail
    monkeypatch.delitem(sys.modules, "envs.drawing.rerun_observer", raising=False)
    module = importlib.import_module("envs.drawing.rerun_observer")
    with pytest.raises(ImportError):
        module.RerunObserver("never.rrd")


def test_the_readme_one_liner_writes_the_file_without_close(tmp_path):
    """`RerunObserver(path).log(frame)` (README): the file is finalised when the observer is collected."""
    import gc

    pytest.importorskip("rerun")
    from envs.drawing.rerun_observer import RerunObserver

    path = tmp_path / "one.rrd"
    RerunObserver(path).log(_episode()[0])
    gc.collect()
    assert [p.name for p in tmp_path.iterdir()] == ["one.rrd"]  # no hidden .part left behind
    assert "/world/pedestrians" in _read(path)


def test_an_unclosed_observer_is_finalised_at_interpreter_exit(tmp_path):
    import subprocess
    import textwrap

    pytest.importorskip("rerun")
    script = textwrap.dedent(f"""
        import sys
        sys.path[:0] = {sys.path!r}
        from tests.envs.test_rerun_observer import _episode
        from envs.drawing.rerun_observer import RerunObserver
        KEEP = RerunObserver({str(tmp_path / "exit.rrd")!r})  # a module global: alive until exit
        for frame in _episode()[:3]:
            KEEP.log(frame)
    """)
    subprocess.run([sys.executable, "-c", script], check=True, timeout=120)
    assert [p.name for p in tmp_path.iterdir()] == ["exit.rrd"]
    assert len(_read(tmp_path / "exit.rrd")["/world/pedestrians"]["step"]) == 3
