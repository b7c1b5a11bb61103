"""``lawn render``: one episode as an animation from the env's own ``rgb_array`` frames."""

import gymnasium as gym
import imageio.v3 as iio
import numpy as np
import pytest

import lawn_env  # noqa: F401
from evaluation.render import record_frames, render_episode, write_animation
from lawn_cli import main


def test_render_writes_a_gif_of_the_episode(tmp_path, capsys):
    out = tmp_path / "episode.gif"
    assert main(["render", "--policy", "epa", "--seed", "2", "--every", "2", "--set", "num_slots=7",
                 "--out", str(out)]) == 0
    frames = iio.imread(out, index=None)
    assert frames.shape[0] == 1 + 3 + 1  # the start, slots 2, 4, 6 and the last (7): kept by the episode's
    # length, not num_slots, so an episode the RL interface ends early keeps its last frame too
    assert frames.shape[1] > 300 and frames.shape[2] > 300
    assert not np.array_equal(frames[0], frames[-1])  # the scene moves
    printed = capsys.readouterr().out
    assert "epa on lawn/Joint-v1, seed 2: control cost" in printed and str(out) in printed


def test_the_frames_are_the_envs_own_and_the_metrics_its_episode(tmp_path):
    frames, metrics, env_id = record_frames("heuristic", "lawn/Joint-v1", seed=1, config={"num_slots": 4})
    env = gym.make("lawn/Joint-v1", num_slots=4, render_mode="rgb_array")
    env.reset(seed=1)
    assert env_id == "lawn/Joint-v1" and len(frames) == 5
    np.testing.assert_array_equal(frames[0], env.render())  # the start, drawn by the env itself
    from agents import make_policy, rollout

    episode = rollout(env, make_policy("heuristic", {"num_slots": 4}), 1)
    assert metrics["control_cost"] == episode.metrics["control_cost"]
    assert env.unwrapped.sim.control_cost == pytest.approx(episode.metrics["control_cost"], rel=1e-12)
    np.testing.assert_array_equal(frames[-1], env.render())


def test_mp4_is_written_too(tmp_path):
    pytest.importorskip("imageio_ffmpeg", reason="MP4 needs imageio-ffmpeg (the video or test extra)")
    result = render_episode("epa", tmp_path / "e.mp4", seed=0, config={"num_slots": 3})
    assert result["frames"] == 4 and (tmp_path / "e.mp4").stat().st_size > 1000


def test_bad_arguments_are_clear_errors(tmp_path, capsys):
    assert main(["render", "--out", str(tmp_path / "e.avi"), "--set", "num_slots=2"]) == 2
    assert "--out" in capsys.readouterr().err
    with pytest.raises(ValueError, match=r"extension must be one of \.gif, \.mp4"):
        write_animation([np.zeros((4, 4, 3), np.uint8)], tmp_path / "x.png")
    with pytest.raises(ValueError, match="fps=0"):
        write_animation([np.zeros((4, 4, 3), np.uint8)], tmp_path / "x.gif", fps=0)
    with pytest.raises(ValueError, match="every=0"):
        record_frames("epa", None, 0, every=0)
    with pytest.raises(ValueError, match="env 'lawn/Nope-v0': unknown"):
        render_episode("epa", tmp_path / "e.gif", env_id="lawn/Nope-v0")
    with pytest.raises(SystemExit):
        main(["render", "--out", str(tmp_path / "e.gif"), "--every", "0"])
    assert "--every" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["render", "--out", str(tmp_path / "e.gif"), "--policy", "nope"])
    assert "unknown policy 'nope'" in capsys.readouterr().err


def test_a_missing_mp4_writer_is_refused_before_the_episode(tmp_path, monkeypatch):
    import sys

    from evaluation import render

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # as if not installed
    played = []
    monkeypatch.setattr(render, "record_frames", lambda *a, **k: played.append(1))
    with pytest.raises(ValueError, match=r"MP4 output needs imageio-ffmpeg: pip install -e \"\.\[video\]\""):
        render_episode("epa", tmp_path / "e.mp4")
    assert not played

