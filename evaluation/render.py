"""One episode shown: its animation (``lawn render``: the env's own ``rgb_array`` frames, one per
slot, written by imageio, GIF through Pillow, MP4 through imageio-ffmpeg) and the demo (``lawn
demo``: the scripted heuristic's episode, its metrics and paths)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, NamedTuple, cast

import gymnasium as gym
import numpy as np

import lawn_env
from agents import HeuristicPolicy, Step, make_policy, rollout
from lawn_env import ScenarioConfig
from lawn_env.envs.base import LawnEnv
from lawn_env.render import plot_episode

__all__ = ["Recording", "FORMATS", "check_output", "record_frames", "write_animation", "render_episode", "run_demo"]

#: Animation formats by file extension.
FORMATS = (".gif", ".mp4")


class Recording(NamedTuple):
    """An episode's frames, its metrics and the env it was played on."""

    frames: list[np.ndarray]
    metrics: dict[str, Any]
    env_id: str


def record_frames(policy: str, env_id: str | None = None, seed: int = 0, config: ScenarioConfig | str | None = None,
                  every: int = 1, progress: bool = False,
                  **policy_args: Any) -> Recording:
    """Play one seeded episode of ``env_id`` (default: the policy's own env) under ``policy`` and
    keep the env's ``rgb_array`` frame of the start and of every ``every``-th slot (and the last),
    with a progress bar over the slots when ``progress``. Returns the frames, the episode's metrics
    (MODEL.md §6) and the env id it ran on."""
    from tqdm.auto import tqdm

    if not isinstance(every, (int, np.integer)) or every < 1:
        raise ValueError(f"every={every!r}: must be a positive integer (keep every n-th slot's frame)")
    actor = make_policy(policy, config, env_id=env_id, **policy_args)
    env_id = env_id or actor.env_id
    env = gym.make(env_id, config=actor.config if config is None else config, render_mode="rgb_array")
    frames: list[np.ndarray] = []

    def frame() -> np.ndarray:
        return cast(np.ndarray, env.render())

    bar = tqdm(total=cast(LawnEnv, env.unwrapped).config.num_slots, desc=policy, unit="slot",
               disable=None if progress else True, leave=False)

    def keep(step: Step) -> None:
        bar.update()
        if (step.slot + 1) % every == 0:  # the frame shows slot n + 1
            frames.append(frame())

    # the start's frame: the reset rollout() does gives the same state for the same seed
    env.reset(seed=seed)
    frames.append(frame())
    try:
        episode = rollout(env, actor, seed, on_step=keep)
    finally:
        bar.close()
    if episode.length % every:  # the episode's last slot (at num_slots, or earlier if it terminated)
        frames.append(frame())
    env.close()
    return Recording(frames, dict(episode.metrics), env_id)


def check_output(out: Path, fps: float = 8.0) -> None:
    """``ValueError`` unless ``out`` names a format of :data:`FORMATS` whose writer is installed and
    ``fps`` is a positive number: checked before an episode is played."""
    suffix = Path(out).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"--out {str(out)!r}: the extension must be one of {', '.join(FORMATS)}")
    if not (fps > 0 and np.isfinite(fps)):
        raise ValueError(f"fps={fps!r}: must be a positive number")
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise ValueError("MP4 output needs imageio-ffmpeg: pip install -e \".[video]\"; "
                             "or write a .gif") from None


def write_animation(frames: list[np.ndarray], out: Path, fps: float = 8.0) -> Path:
    """Write ``frames`` (H x W x 3 uint8) as an animation, its format by ``out``'s extension
    (:data:`FORMATS`); a GIF loops forever."""
    import imageio.v3 as iio

    out = Path(out)
    check_output(out, fps)
    out.parent.mkdir(parents=True, exist_ok=True)
    stack = np.stack(frames)
    if out.suffix.lower() == ".gif":
        iio.imwrite(out, stack, extension=".gif", duration=1000.0 / fps, loop=0)
    else:
        iio.imwrite(out, stack, extension=".mp4", plugin="FFMPEG", fps=fps, macro_block_size=1)
    return out


def render_episode(policy: str, out: Path, env_id: str | None = None, fps: float = 8.0,
                   **options: Any) -> dict[str, Any]:
    """One seeded episode of ``env_id`` under ``policy`` as an animation at ``out`` (GIF or MP4);
    returns the episode's metrics with the env id, frame count and file. ``options``: the ``seed``,
    ``config``, ``every``, ``progress`` and policy settings of :func:`record_frames`."""
    if env_id is not None and env_id not in lawn_env.ENV_IDS and env_id not in lawn_env.RL_ENV_IDS:
        raise ValueError(f"env {env_id!r}: unknown; valid: {', '.join([*lawn_env.ENV_IDS, *lawn_env.RL_ENV_IDS])}")
    check_output(Path(out), fps)
    frames, metrics, env_id = record_frames(policy, env_id, **options)
    path = write_animation(frames, out, fps)
    return {**metrics, "env_id": env_id, "frames": len(frames), "out": str(path)}


def run_demo(seed: int, out_dir: Path, config: ScenarioConfig | str | None = None,
             overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run one episode, write ``metrics.json`` and ``paths.png`` into ``out_dir``; return the metrics."""
    env = gym.make("lawn/Joint-v1", config=config, **(overrides or {}))
    lawn = cast(LawnEnv, env.unwrapped)
    episode = rollout(env, HeuristicPolicy(lawn.config), seed)
    metrics = dict(episode.metrics)
    metrics["decision_time_median_s"] = episode.decision_time_median_s
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2))

    plot_episode(lawn.sim, lawn.engine.kept_trail, out_dir / "paths.png",
                 title=f"lawn/Joint-v1, scripted heuristic, seed {seed}: cost {metrics['control_cost']:.0f}")
    env.close()
    return metrics
