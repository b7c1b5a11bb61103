"""Episode traces for the path figures: the drone's, the AGVs' and the references' positions of
one episode per case, as table rows (:func:`trace_rows`), and their plot (:func:`plot_traces`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

from agents import make_policy, rollout
from lawn_env import presets
from lawn_env.envs import JointEnv

from .base import QUICK_SET
from .plots import new_figure, save

__all__ = ["trace_rows", "plot_traces"]


def trace_rows(cases: Sequence[tuple[str, str, str]], quick: bool) -> list[dict[str, Any]]:
    """Drone, AGV and reference positions of one episode (seed 0) per (label, preset, policy)."""
    import gymnasium as gym


    rows = []
    for label, preset, policy in cases:
        cfg = presets.get(preset).override(QUICK_SET) if quick else presets.get(preset)
        env = cast(JointEnv, gym.make("lawn/Joint-v1", config=cfg).unwrapped)
        cost = rollout(env, make_policy(policy, cfg), 0).metrics["control_cost"]
        traj = env.trajectories()
        for n in range(traj["drone_position"].shape[0]):
            base = {"case": label, "preset": preset, "policy": policy, "slot": n, "control_cost": cost}
            rows.append({**base, "who": "drone", "x": traj["drone_position"][n, 0], "y": traj["drone_position"][n, 1]})
            for i in range(cfg.num_agvs):
                for who, arr in (("agv", traj["agv_position"]), ("reference", traj["reference_position"])):
                    rows.append({**base, "who": f"{who}_{i}", "x": arr[n, i, 0], "y": arr[n, i, 1]})
    return rows


def plot_traces(rows: Sequence[dict[str, Any]], path: Path, cases: Sequence[tuple[str, str, str]]) -> None:
    fig = new_figure(ncols=len(cases), width=3.3, height=3.6)
    for j, (label, preset, policy) in enumerate(cases):
        ax = fig.add_subplot(1, len(cases), j + 1)
        sel = [r for r in rows if r["case"] == label and r["policy"] == policy]
        k = len({r["who"] for r in sel if r["who"].startswith("agv_")})
        for i in range(k):
            for who, ls in (("reference", "--"), ("agv", "-")):
                pts = [(float(r["x"]), float(r["y"])) for r in sel if r["who"] == f"{who}_{i}"]
                ax.plot(*zip(*pts, strict=True), ls, color=f"C{i}", lw=0.9 if who == "reference" else 1.3)
        drone = [(float(r["x"]), float(r["y"])) for r in sel if r["who"] == "drone"]
        ax.plot(*zip(*drone, strict=True), "-", color="k", lw=1.2)
        ax.plot(*drone[-1], "k^", ms=6)
        x0, x1, y0, y1 = presets.get(preset).area_m
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.set_title(f"{label}, {policy}: cost {float(sel[0]['control_cost']):,.0f}", fontsize=8)
    save(fig, path)
