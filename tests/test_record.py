"""Recording: geometry, episode choice, exact read-back of curves, episodes and metadata."""

from __future__ import annotations

import gc
import math
from pathlib import Path

import foxglove
import mujoco
import numpy as np
import pandas as pd
import pytest
from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Timestamp, Vector3
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory

from evo.config import typed
from evo.edge import compose_config
from evo.envs.arena import ArenaParams
from evo.envs.scene import build_scene
from evo.envs.tasks.reach import Reach
from evo.record import (
    Episode,
    EpisodeChoice,
    McapRecorder,
    NullRecorder,
    RecordConfig,
    RecordError,
    Recorders,
    is_complete,
    open_recorder,
    read_curve,
    read_episodes,
    read_json_topic,
    read_metadata,
    scene_geometry,
    should_record,
)
from evo.record.rows import decode_row, encode_row
from evo.record.transforms import TransformEncoder
from evo.robot import load_robot
from evo.robot.builder import PhysicsParams, build


def scene(n_rocks: int = 3) -> mujoco.MjModel:
    """The four-wheeler in an arena with ``n_rocks`` rocks and the target marker."""
    robot = load_robot("robots/four_wheeler.json")
    arena = ArenaParams(n_rocks=n_rocks)
    return build_scene(robot, PhysicsParams(), arena, Reach()).compile()


def simulate(model: mujoco.MjModel, frames: int, index: int = 0, seed: int = 0) -> Episode:
    """A real episode: rocks spread out, motors driven, poses copied every control step."""
    rng = np.random.default_rng(seed)
    data = mujoco.MjData(model)
    for i in range(model.nbody):
        name = model.body(i).name
        if name.startswith("rock"):
            adr = model.joint(name).qposadr[0]
            data.qpos[adr : adr + 2] = rng.uniform(-1.5, 1.5, size=2)
    target = np.array([0.8, -0.3, 0.0])
    data.mocap_pos[0] = target
    time, xpos, xquat = [], [], []
    for _ in range(frames):
        data.ctrl[:] = rng.uniform(-1, 1, size=model.nu)
        for _ in range(10):
            mujoco.mj_step(model, data)
        time.append(data.time)
        xpos.append(data.xpos.copy())
        xquat.append(data.xquat.copy())
    rewards = {
        "time": np.full(frames, -1e-3),
        "approach": rng.normal(scale=1e-3, size=frames),
        "success": np.r_[np.zeros(frames - 1), 1.0],
    }
    return Episode(
        index=index,
        env_step=1000 * (index + 1),
        time=np.array(time),
        xpos=np.array(xpos),
        xquat=np.array(xquat),
        target=target,
        rewards=rewards,
        success=True,
    )


def curve_rows(n: int) -> list[dict[str, float]]:
    """Rows shaped like the learner's, with NaN, infinities, ints and signed zero."""
    rows = []
    for i in range(n):
        rows.append(
            {
                "env_steps": float(2048 * (i + 1)),
                "train/episodes": float(i % 3),
                "train/mean_return": math.nan if i % 3 == 0 else 0.1 * i + 1e-17,
                "train/success_rate": 1 / 3,
                "train/reward/time": -0.001,
                "train/reward/approach": -0.0 if i == 1 else 1e-300 * i,
                "train/loss/objective": math.inf if i == 2 else -math.inf if i == 3 else 0.25,
                "train/loss/critic": 12345678.901234567,
                "train/lr": 3e-4,
                "wall_seconds": float(i),
            }
        )
    return rows


# --- pure pieces -------------------------------------------------------------------


def test_transform_encoder_matches_the_official_encoder() -> None:
    rng = np.random.default_rng(1)
    names = ["brain", "wheel3", "a-much-longer-body-name_with_digits_0123456789"]
    pos, quat = rng.normal(size=(6, 3, 3)), rng.normal(size=(6, 3, 4))
    pos[0, 0, 1] = 0.0  # a zero double: written explicitly, parsed the same
    stamps = [0, 1, 999_999_999, 1_000_000_000, 123_456_789_012, 2**32 * 10**9 - 1]
    ours = TransformEncoder(names).encode(stamps, pos, quat)
    schema = FrameTransforms.get_schema()
    decode = DecoderFactory().decoder_for(
        "protobuf", Schema(id=1, name=schema.name, encoding=schema.encoding, data=schema.data)
    )
    assert decode is not None
    for t, stamp in enumerate(stamps):
        official = FrameTransforms(
            transforms=[
                FrameTransform(
                    timestamp=Timestamp(sec=stamp // 10**9, nsec=stamp % 10**9),
                    parent_frame_id="world",
                    child_frame_id=name,
                    translation=Vector3(x=pos[t, b, 0], y=pos[t, b, 1], z=pos[t, b, 2]),
                    rotation=Quaternion(
                        x=quat[t, b, 1], y=quat[t, b, 2], z=quat[t, b, 3], w=quat[t, b, 0]
                    ),
                )
                for b, name in enumerate(names)
            ]
        ).encode()
        assert decode(ours[t]) == decode(official), f"frame {t} decodes differently"
        if t > 0:
            assert ours[t] == official, f"frame {t}: bytes differ from foxglove's encoder"


def test_geometry_sits_where_mujoco_puts_the_geoms() -> None:
    model = scene(n_rocks=5)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    geometry = scene_geometry(model)
    posed = geometry.posed(data.xpos, data.xquat)
    kinds = {model.geom(int(g)).name: k for g, k in zip(geometry.geom, geometry.kind, strict=True)}
    assert kinds["brain"] == "box" and kinds["wheel3"] == "cylinder"
    assert {kinds[f"rock{i}"] for i in range(5)} == {"box", "ellipsoid", "cylinder"}
    assert kinds["target"] == "cylinder" and kinds["floor"] == "box"
    for i, g in enumerate(geometry.geom):
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE:
            assert posed.pos[i, 2] + posed.half_size[i, 2] == pytest.approx(0.0)
            continue
        np.testing.assert_allclose(
            posed.pos[i],
            data.geom_xpos[g],
            atol=1e-12,
            err_msg=f"geom {model.geom(int(g)).name} centre",
        )
        mat = np.zeros(9)
        mujoco.mju_quat2Mat(mat, posed.quat[i])
        np.testing.assert_allclose(
            mat,
            data.geom_xmat[g],
            atol=1e-12,
            err_msg=f"geom {model.geom(int(g)).name} orientation",
        )
    brain = geometry.of_body(geometry.body_names.index("brain"))
    np.testing.assert_allclose(brain.half_size[0], model.geom("brain").size)
    motor = model.geom("motor2")
    assert tuple(geometry.rgba[list(geometry.geom).index(motor.id)]) == tuple(
        model.mat_rgba[motor.matid[0]]
    ), "the material's colour wins over the default grey"


def test_capsules_become_a_cylinder_and_two_spheres() -> None:
    model = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body name="b"><geom type="capsule" size="0.1 0.3"/>'
        '<geom type="sphere" size="0.2" group="3"/></body></worldbody></mujoco>'
    )
    geometry = scene_geometry(model)
    assert geometry.kind == ("cylinder", "ellipsoid", "ellipsoid"), "group-3 geoms are hidden"
    np.testing.assert_allclose(geometry.pos[1:, 2], [-0.3, 0.3])
    np.testing.assert_allclose(geometry.half_size, [[0.1, 0.1, 0.3], [0.1] * 3, [0.1] * 3])


@pytest.mark.parametrize(
    ("choice", "expected"),
    [
        (EpisodeChoice(first=True, last=True, every=0), [0, 9]),
        (EpisodeChoice(first=False, last=False, every=4), [0, 4, 8]),
        (EpisodeChoice(first=True, last=True, every=4), [0, 4, 8, 9]),
        (EpisodeChoice(first=False, last=True, every=0), [9]),
    ],
)
def test_should_record_picks_first_last_and_every_kth(
    choice: EpisodeChoice, expected: list[int]
) -> None:
    config = RecordConfig(episodes=choice)
    picked = [i for i in range(10) if should_record(config, i, is_last=i == 9)]
    assert picked == expected
    off = RecordConfig(mcap=False, rerun=False, episodes=choice)
    assert not any(should_record(off, i, is_last=i == 9) for i in range(10))


@pytest.mark.parametrize("name", ["default", "off"])
def test_record_configs_compose_to_what_they_choose(name: str) -> None:
    # What each key means is RecordConfig's docstring (tests/test_schemas.py checks it).
    config = typed(RecordConfig, compose_config([f"record={name}"]).record, "record")
    nothing = EpisodeChoice(first=False, last=False, every=0)
    assert config == (RecordConfig() if name == "default"
                      else RecordConfig(mcap=False, rerun=False, episodes=nothing))
    assert config.enabled == (name == "default")


def test_bad_record_config_values_are_refused() -> None:
    with pytest.raises(ValueError, match="frame_stride"):
        RecordConfig(frame_stride=0)
    with pytest.raises(ValueError, match="every"):
        EpisodeChoice(every=-1)


def test_rows_nest_when_exact_and_stay_flat_otherwise() -> None:
    nested = {"env_steps": 1.0, "loss/a": 2.0, "loss/b": 3.0}
    assert encode_row(nested) == b'{"env_steps":1.0,"loss":{"a":2.0,"b":3.0}}'
    interleaved = {"loss/a": 1.0, "x": 2.0, "loss/b": 3.0}
    clash = {"loss": 1.0, "loss/a": 2.0}
    deep = {"a/b/c": 1.0, "a/b/d": 2.0, "a/e": math.nan}
    for row in (nested, interleaved, clash, deep):
        back = decode_row(encode_row(row))
        assert list(back) == list(row), f"key order of {row}"
        assert [str(v) for v in back.values()] == [str(v) for v in row.values()]
    assert b'"x"' in encode_row(interleaved) and b'"loss/a"' in encode_row(interleaved)


def test_episode_validates_its_arrays() -> None:
    t = np.arange(3.0)
    with pytest.raises(ValueError, match="xquat"):
        Episode(0, 0, t, np.zeros((3, 2, 3)), np.zeros((3, 2, 3)), np.zeros(3))
    with pytest.raises(ValueError, match="reward 'time'"):
        Episode(
            0, 0, t, np.zeros((3, 2, 3)), np.zeros((3, 2, 4)), np.zeros(3), {"time": np.zeros(2)}
        )
    with pytest.raises(ValueError, match="strictly increasing"):
        Episode(0, 0, np.zeros(3), np.zeros((3, 2, 3)), np.zeros((3, 2, 4)), np.zeros(3))


def test_stride_keeps_the_return_and_the_last_frame() -> None:
    episode = simulate(scene(), frames=23)
    strided = episode.strided(5)
    assert strided.frames == 6
    np.testing.assert_array_equal(strided.time, episode.time[[0, 5, 10, 15, 20, 22]])
    for term, values in episode.rewards.items():
        assert strided.rewards[term].sum() == pytest.approx(values.sum(), abs=1e-15)
    assert strided.rewards["success"][-1] == 1.0


# --- MCAP round trips --------------------------------------------------------------


def test_curve_reads_back_exactly(tmp_path: Path) -> None:
    rows = curve_rows(13)
    rows[7]["eval/late_key"] = 7.0  # a column that appears late
    path = tmp_path / "evals" / "robot-00000001.mcap"
    with McapRecorder(path, scene(), {"seed": 3}, flush_every=4) as rec:
        for row in rows:
            rec.curve(row)
    curve = read_curve(path)
    pd.testing.assert_frame_equal(curve, pd.DataFrame(rows), check_exact=True)
    assert list(curve.columns) == list(pd.DataFrame(rows).columns)
    assert math.copysign(1.0, curve["train/reward/approach"][1]) == -1.0, "-0.0 keeps its sign"


def test_curves_recorded_before_metric_keys_were_namespaced_load_under_the_new_names(
    tmp_path: Path,
) -> None:
    """A recording (MCAP or CSV) with the old unprefixed keys reads back as one made now."""
    rows = curve_rows(4)
    old = [{k.removeprefix("train/"): v for k, v in row.items()} for row in rows]
    assert "mean_return" in old[0] and "loss/critic" in old[0]
    with McapRecorder(tmp_path / "old.mcap", scene(), {"seed": 3}) as rec:
        for row in old:
            rec.curve(row)
    pd.DataFrame(old).to_csv(tmp_path / "old.csv", index=False)
    for path in (tmp_path / "old.mcap", tmp_path / "old.csv"):
        pd.testing.assert_frame_equal(read_curve(path), pd.DataFrame(rows), check_exact=True,
                                      check_dtype=path.suffix == ".mcap")


def robot_bodies(model: mujoco.MjModel) -> np.ndarray:
    """Ids of the robot's bodies (the tree under ``brain``)."""
    return np.flatnonzero(model.body_rootid == model.body("brain").id)


@pytest.mark.parametrize("tolerance", [0.0, 1e-6])
def test_episode_poses_equal_the_simulator(tmp_path: Path, tolerance: float) -> None:
    model = scene(n_rocks=4)
    episodes = [simulate(model, frames=120, index=i, seed=i) for i in (0, 7)]
    episodes[1].rewards["approach"][5] = math.nan  # non-finite values take the slow path
    path = tmp_path / "e.mcap"
    with McapRecorder(path, model, {"seed": 1}, still_tolerance=tolerance) as rec:
        for episode in episodes:
            rec.episode(episode)
    back = read_episodes(path)
    assert [e.index for e in back] == [0, 7]
    robot = robot_bodies(model)
    for want, got in zip(episodes, back, strict=True):
        assert got.env_step == want.env_step and got.success == want.success
        np.testing.assert_array_equal(got.time, want.time)
        np.testing.assert_array_equal(got.xpos[:, robot], want.xpos[:, robot])
        np.testing.assert_array_equal(got.xquat[:, robot], want.xquat[:, robot])
        if tolerance == 0.0:
            np.testing.assert_array_equal(got.xpos[:, 1:], want.xpos[:, 1:])
            np.testing.assert_array_equal(got.xquat[:, 1:], want.xquat[:, 1:])
        else:  # rocks at rest come back at their first pose, within the tolerance
            np.testing.assert_allclose(got.xpos[:, 1:], want.xpos[:, 1:], rtol=0, atol=tolerance)
            np.testing.assert_allclose(got.xquat[:, 1:], want.xquat[:, 1:], rtol=0, atol=tolerance)
        np.testing.assert_array_equal(got.target, want.target)
        assert list(got.rewards) == list(want.rewards)
        for term in want.rewards:
            np.testing.assert_array_equal(got.rewards[term], want.rewards[term])
    target = model.body("target").id
    assert np.all(back[0].xpos[:, target] == episodes[0].xpos[0, target]), "the target is still"
    info = read_json_topic(path, "/episode")[0]
    assert "target" in info["still"] and "brain" in info["moving"], "still bodies written once"


def test_stride_applies_to_the_recording(tmp_path: Path) -> None:
    model = scene(n_rocks=0)
    episode = simulate(model, frames=31)
    path = tmp_path / "s.mcap"
    with McapRecorder(path, model, {}, frame_stride=10) as rec:
        rec.episode(episode)
    (got,) = read_episodes(path)
    want = episode.strided(10)
    np.testing.assert_array_equal(got.xpos[:, 1:], want.xpos[:, 1:])
    np.testing.assert_array_equal(got.rewards["time"], want.rewards["time"])


def test_metadata_and_summary_read_back(tmp_path: Path) -> None:
    robot_json = Path("robots/four_wheeler.json").read_text()
    metadata = {
        "robot": robot_json,
        "config": "seed: 3\nlearner:\n  name: ppo\n",
        "seed": 3,
        "method": "E+L",
        "budget": [50000, 250000],
        "note": {"a": 1},
    }
    path = tmp_path / "m.mcap"
    rec = McapRecorder(path, scene(), metadata)
    rec.close({"fitness": -0.125, "episodes": 40})
    rec.close({"fitness": 1.0})  # a second close does nothing
    assert read_metadata(path) == {**metadata, "fitness": -0.125, "episodes": 40}
    assert is_complete(path)
    with pytest.raises(RecordError, match="m.mcap: the recorder is closed"):
        rec.curve({"env_steps": 1.0})


def test_exception_inside_with_closes_the_file(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    with pytest.raises(RuntimeError, match="boom"), McapRecorder(path, scene(), {}) as rec:
        rec.curve({"env_steps": 1.0})
        raise RuntimeError("boom")
    assert is_complete(path)
    meta = read_metadata(path)
    assert meta["status"] == "failed" and "boom" in meta["error"]


def test_closed_recorders_leave_no_channel_behind(tmp_path: Path) -> None:
    def channels() -> int:
        gc.collect()
        return sum(isinstance(o, foxglove.Channel) for o in gc.get_objects())

    model, before = scene(), channels()
    for i in range(3):
        with McapRecorder(tmp_path / f"{i}.mcap", model, {}) as rec:
            rec.curve({"env_steps": 1.0})
    del rec
    assert channels() == before, "every recorded evaluation would keep its channels"
    assert read_curve(tmp_path / "2.mcap")["env_steps"].tolist() == [1.0]


def test_truncated_files_give_a_prefix_of_the_rows(tmp_path: Path) -> None:
    rows = curve_rows(30)
    path = tmp_path / "t.mcap"
    with McapRecorder(path, scene(n_rocks=0), {}, flush_every=3) as rec:
        for row in rows:
            rec.curve(row)
    data = path.read_bytes()
    seen = []
    for cut in np.linspace(200, len(data) - 1, 25).astype(int):
        part = tmp_path / f"cut{cut}.mcap"
        part.write_bytes(data[:cut])
        curve = read_curve(part)
        expected = pd.DataFrame(rows[: len(curve)])
        if len(curve):
            pd.testing.assert_frame_equal(curve, expected, check_exact=True)
        assert not is_complete(part)
        seen.append(len(curve))
    assert seen == sorted(seen) and seen[-1] >= 27, f"rows recovered per cut: {seen}"


def test_wrong_files_and_episodes_raise_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nothing.mcap"):
        read_curve(tmp_path / "nothing.mcap")
    text = tmp_path / "notes.mcap"
    text.write_text("hello, this is not a recording")
    with pytest.raises(RecordError, match="notes.mcap"):
        read_curve(text)
    path = tmp_path / "w.mcap"
    with McapRecorder(path, scene(n_rocks=2), {}) as rec:
        with pytest.raises(ValueError, match="w.mcap.*bodies"):
            rec.episode(simulate(scene(n_rocks=0), frames=3))
        with pytest.raises(KeyError, match="env_steps"):
            rec.curve({"train/mean_return": 1.0})


def test_open_recorder_follows_the_config(tmp_path: Path) -> None:
    model = build(load_robot("robots/snake.json")).compile()
    off = RecordConfig(mcap=False, rerun=False)
    assert isinstance(open_recorder(off, tmp_path, "robot-0", model, {}), NullRecorder)
    mcap_only = RecordConfig(rerun=False)
    with open_recorder(mcap_only, tmp_path / "evals", "robot-1", model, {"seed": 2}) as rec:
        assert isinstance(rec, Recorders)
        rec.curve({"env_steps": 1.0})
    assert sorted(p.name for p in (tmp_path / "evals").iterdir()) == ["robot-1.mcap"]
    assert read_metadata(tmp_path / "evals" / "robot-1.mcap") == {"name": "robot-1", "seed": 2}
