"""Matplotlib rendering of a simulation: area, reference paths, AGVs, drone, links.

Links are colored by their outage probability (log scale, 1e-6 .. 1, with a colour bar); the title
shows the slot and the control cost so far. ``rgb_array`` draws on an off-screen Agg canvas;
``human`` opens a pyplot window and refreshes it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .dynamics import POSITION

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.colors import Colormap, LogNorm
    from matplotlib.figure import Figure

    from .config import ScenarioConfig
    from .core import ScenarioView, Trail

__all__ = ["Renderer", "plot_episode"]


#: The links' colour scale: outage probability on a log scale, green (rare) to red (likely).
_OUTAGE_RANGE = (1e-6, 1.0)
_OUTAGE_CMAP = "RdYlGn_r"


def _outage_scale() -> tuple[LogNorm, Colormap]:
    from matplotlib import colormaps, colors

    return colors.LogNorm(*_OUTAGE_RANGE), colormaps[_OUTAGE_CMAP]


def _axes(fig: Figure) -> Axes:
    """The scene's axes and, beside them, the links' colour bar, at fixed places (a frame depends
    on the state it shows alone, not on the frames drawn before it)."""
    from matplotlib.cm import ScalarMappable

    ax = fig.add_axes((0.1, 0.09, 0.68, 0.84))
    norm, cmap = _outage_scale()
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=fig.add_axes((0.84, 0.16, 0.03, 0.7)),
                 label="link outage probability")
    return ax


def _draw(ax: Axes, sim: ScenarioView, trail: Trail, *, links: bool = True, trails: bool = True,
          title: str | None = None) -> Axes:
    from matplotlib import cm

    x0, x1, y0, y1 = sim.area
    ax.clear()
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    k = sim.num_agvs
    palette = [cm.tab10(i % 10) for i in range(k)]
    ref = sim.reference[:, : sim.num_slots + 1]
    for i in range(k):
        ax.plot(ref[i, :, 0], ref[i, :, 1], "--", color=palette[i], lw=0.8, alpha=0.6)
    traj = trail.trajectories()
    agv = traj["agv_position"]
    if trails and len(agv) > 1:
        for i in range(k):
            ax.plot(agv[:, i, 0], agv[:, i, 1], "-", color=palette[i], lw=1.4)
    pos = sim.x_aug[:, POSITION]
    ax.scatter(pos[:, 0], pos[:, 1], c=palette, s=30, zorder=3, label="AGVs")
    q = sim.drone_position
    flown = traj["drone_position"]
    if trails and len(flown) > 1:
        ax.plot(flown[:, 0], flown[:, 1], "-", color="k", lw=1.0, alpha=0.7)
    ax.scatter([q[0]], [q[1]], marker="^", c="k", s=80, zorder=4, label="drone")
    if links:
        norm, cmap = _outage_scale()
        outage = np.clip(sim.last_outage_probability, *_OUTAGE_RANGE)
        for i in range(k):
            ax.plot([q[0], pos[i, 0]], [q[1], pos[i, 1]], color=cmap(norm(outage[i])), lw=2.0, zorder=2)
    ax.set_title(title or f"slot {sim.slot}/{sim.num_slots}, control cost so far {sim.control_cost:,.1f}")
    return ax


class Renderer:
    def __init__(self, config: ScenarioConfig, human: bool = False):
        self.human = human
        if human:
            import matplotlib.pyplot as plt

            self._plt = plt
            plt.ion()
            self.fig = plt.figure(figsize=(6.4, 5.6))
            self.ax = _axes(self.fig)
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.fig = Figure(figsize=(6.4, 5.6), dpi=80)
            self.canvas = FigureCanvasAgg(self.fig)
            self.ax = _axes(self.fig)

    def draw(self, sim: ScenarioView, trail: Trail) -> np.ndarray | None:
        """One frame of a scenario (a :class:`~lawn_env.core.ScenarioView`: state row i) with its trail."""
        _draw(self.ax, sim, trail)
        if self.human:
            self.fig.canvas.draw_idle()
            self._plt.pause(0.001)
            return None
        self.canvas.draw()
        frame: np.ndarray = np.asarray(self.canvas.buffer_rgba())[:, :, :3].copy()
        return frame

    def close(self) -> None:
        if self.human:
            self._plt.close(self.fig)


def plot_episode(sim: ScenarioView, trail: Trail, path: str | Path, title: str | None = None) -> None:
    """Save a PNG (or any matplotlib format, by extension) of one scenario's finished or running
    episode: a single env's ``env.unwrapped.sim`` and ``env.unwrapped.engine.trail``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.6, 7), dpi=110)
    FigureCanvasAgg(fig)
    ax = _axes(fig)
    _draw(ax, sim, trail, title=title)
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(path)
