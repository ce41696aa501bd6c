"""Figures: success by level, the critic's value over a tile, training curves."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from mjx_stairs import atomic
from mjx_stairs.rl import logger


def plot_critic_map(m: dict[str, np.ndarray], path: str | os.PathLike, title: str = "") -> None:
    """Heat map of the critic's value with the terrain's contours, goal and centre-line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 5.2), dpi=110)
    im = ax.imshow(m["value"], origin="lower", extent=m["extent"], cmap="viridis")
    x0, x1, y0, y1 = m["extent"]
    hy, hx = m["heights"].shape
    ax.contour(
        np.linspace(x0, x1, hx),
        np.linspace(y0, y1, hy),
        m["heights"],
        levels=12,
        colors="white",
        linewidths=0.4,
        alpha=0.6,
    )
    ax.plot(m["centreline"][:, 0], m["centreline"][:, 1], "w--", lw=1, label="centre-line")
    ax.plot(m["goal"][0], m["goal"][1], "r*", ms=14, label="goal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or "critic value")
    ax.legend(loc="upper right", fontsize=7)
    fig.colorbar(im, ax=ax, label="V")
    fig.tight_layout()
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def plot_success(
    curves: dict[str, dict[str, Any]],
    path: str | os.PathLike,
    paper: dict[int, float] | None = None,
    title: str = "U-shaped stairs: success by test level",
) -> None:
    """Success against level for several policies, the paper's points overlaid."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), dpi=110)
    for name, r in curves.items():
        ax.plot(r["levels"], [100 * s for s in r["success"]], "o-", label=name)
    if paper:
        lv = sorted(paper)
        ax.plot(lv, [paper[k] for k in lv], "k*", ms=12, label="paper (Table 1)")
    ax.set_xlabel("test level (riser 4, 6, 8, 10, 12, 14 cm)")
    ax.set_ylabel("success (%)")
    ax.set_ylim(-3, 103)
    ax.grid(alpha=0.3)
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


CURVE_KEYS = (
    ("success", "success (share of ended episodes)"),
    ("level", "mean curriculum level (0-based)"),
    ("episode/return", "episode return"),
)


def read_metrics(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The rows of a run's metrics (a run or published directory, or its metrics.jsonl)."""
    p = Path(path)
    rows = logger.read_jsonl(p / "metrics.jsonl" if p.is_dir() else p)
    if not rows or "env_steps" not in rows[0]:
        raise ValueError(f"{p}: no training rows (env_steps missing)")
    return rows


def plot_curves(runs: dict[str, str | os.PathLike], path: str | os.PathLike) -> None:
    """Training curves against env steps: success, mean level and return, one line per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = {name: read_metrics(p) for name, p in runs.items()}
    fig, axes = plt.subplots(1, len(CURVE_KEYS), figsize=(5 * len(CURVE_KEYS), 3.6), dpi=100)
    for ax, (key, label) in zip(axes, CURVE_KEYS, strict=True):
        for name, rows in data.items():
            xs = [r["env_steps"] / 1e6 for r in rows if key in r]
            ax.plot(xs, [r[key] for r in rows if key in r], label=name, lw=1.2)
        ax.set_xlabel("env steps (M)")
        ax.set_title(label, fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
