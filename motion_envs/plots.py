"""Plot helpers used by every benchmark: top-down paths with goals and obstacles, success by goal
placement, learning curves; figures are saved atomically. Matplotlib with the Agg backend (no display)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from motion_envs.atomic import atomic_write  # noqa: E402
from motion_envs.scenes.scene import Scene  # noqa: E402

BAR_COLOURS = ("#d9a400", "#2e9e4f", "#2f6fd0", "#b0413e")


def grid_of_axes(panels: int, columns: int = 4, size: float = 4.0) -> tuple[Figure, list[Axes]]:
    """A figure with `panels` square axes in rows of at most `columns` (unused cells hidden)."""
    columns = max(1, min(columns, panels))
    rows = -(-panels // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(size * columns, size * rows), squeeze=False)
    for axis in axes.flat[panels:]:
        axis.axis("off")
    return figure, list(axes.flat[:panels])


def top_down(axis: Axes, paths: np.ndarray, goals: np.ndarray | None = None, scene: Scene | None = None,
             title: str | None = None, extent: float | None = None) -> None:  # fmt: skip
    """Pelvis paths seen from above. paths: (N, T, 2) metres (NaN after a path ends); goals: (N, 2) or (G, 2);
    scene: its obstacles (any solid over the floor) in grey; extent: half-width of a square view around 0."""
    if scene is not None:
        grid = scene.grid
        obstacles = grid.occupied.any(axis=2).T
        x0, y0 = grid.origin[:2]
        x1, y1 = x0 + grid.occupied.shape[0] * grid.pitch, y0 + grid.occupied.shape[1] * grid.pitch
        axis.imshow(np.where(obstacles, 0.35, 1.0), cmap="gray", vmin=0, vmax=1, origin="lower", extent=(x0, x1, y0, y1))
    for path in np.asarray(paths):
        axis.plot(path[:, 0], path[:, 1], linewidth=0.8)
    if goals is not None:
        goals = np.asarray(goals)
        axis.scatter(goals[:, 0], goals[:, 1], marker="x", color="black", s=14, zorder=3)
    if extent is not None:
        axis.set(xlim=(-extent, extent), ylim=(-extent, extent))
    axis.set(aspect="equal", xlabel="x (m)", ylabel="y (m)")
    if title:
        axis.set_title(title)


def success_by(axes: Sequence[Axes], panels: dict[str, tuple[Sequence[str], dict[str, Sequence[float]]]],
               ylabel: str = "success rate (%)") -> None:  # fmt: skip
    """One bar chart per panel: {x-axis label: (tick labels, {series: success values})} (e.g. by goal height, angle,
    distance); several series are grouped side by side, with a legend."""
    for axis, (name, (ticks, series)) in zip(axes, panels.items()):
        width = 0.8 / len(series)
        for index, (label, values) in enumerate(series.items()):
            offsets = np.arange(len(ticks)) + (index - (len(series) - 1) / 2) * width
            axis.bar(offsets, list(values), width=width, color=BAR_COLOURS[index % len(BAR_COLOURS)], label=label)
        axis.set_xticks(range(len(ticks)), list(ticks))
        axis.set_xlabel(name)
        axis.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel(ylabel)
    if len(series) > 1:
        axes[0].set_ylim(0, 130)  # room for the legend above 100%
        axes[0].legend(fontsize=7, loc="upper left")


def learning_curves(by_steps: Axes, by_time: Axes | None, curves: dict[str, Sequence[dict]], value: str = "success_rate",
                    steps_label: str = "env steps") -> None:  # fmt: skip
    """Curves {label: [{"timesteps", "wall_seconds", value}, ...]} against steps and (optionally) wall minutes."""
    for label, curve in curves.items():
        steps = [point["timesteps"] for point in curve]
        values = [point[value] for point in curve]
        by_steps.plot(steps, values, label=label)
        if by_time is not None:
            by_time.plot([point["wall_seconds"] / 60 for point in curve], values, label=label)
    by_steps.set(xlabel=steps_label, ylabel=value.replace("_", " "))
    if by_time is not None:
        by_time.set(xlabel="wall time (min)")
    by_steps.legend()


def save(figure: Figure, path: str | Path, dpi: int = 100) -> Path:
    """Write `figure` as PNG atomically and close it."""
    figure.tight_layout()
    written = atomic_write(path, lambda file: figure.savefig(file, format="png", dpi=dpi))
    plt.close(figure)
    return written
