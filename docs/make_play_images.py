"""Make docs/play_frame.png and docs/mcap_plot.png (the images of docs/play_and_export.md).

    python docs/make_play_images.py                       # a fresh, untrained policy
    python docs/make_play_images.py --checkpoint experiments/results/stage2_u/policy.npz

Without --checkpoint the policy is a fresh one from the trainer's `init` (random weights, as
training starts), saved with `save_policy`: the images then show the tooling, not a skill.
The frame is rendered exactly as `mjx-stairs play --video` renders (MuJoCo renderer, camera
"track"); the plot is drawn from the MCAP that `mjx-stairs play --mcap` writes, read back with
the mcap reader.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from mjx_stairs.tools import play  # noqa: E402  (first: it sets MUJOCO_GL before mujoco is imported)

# isort: split
from mjx_stairs.atomic import atomic_path  # noqa: E402


def fresh_policy(path: Path, seed: int = 0) -> None:
    """An untrained policy: trainer.init of a small config, written with save_policy."""
    import jax

    from mjx_stairs.config import apply_overrides, from_dict
    from mjx_stairs.rl import checkpointer
    from mjx_stairs.rl import trainer as trainer_lib
    from mjx_stairs.study import experiment

    data = apply_overrides({}, [
        'terrain.families=["u_shaped"]', "terrain.levels=[0]", "terrain.variants_per_family=1",
        "terrain.resolution=0.1", "train.num_envs=4", "train.unroll_length=4",
    ])
    config = from_dict(experiment.ExperimentConfig, data)
    env = experiment.make_env(config)
    trainer = trainer_lib.build_trainer(config, env)
    state = trainer.init(jax.random.PRNGKey(seed))
    checkpointer.save_policy(path, state, config, trainer.layout)


def plot_mcap(mcap_path: Path, out: Path, title: str) -> None:
    """A viewer-like summary of an MCAP from `play`: top view (terrain mesh, base paths, goal),
    reward terms of robot 0, and robot 0's front-left joint angles, all read from the file."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.collections import PolyCollection

    from mjx_stairs.tools import mcap_log

    log = mcap_log.read_mcap(mcap_path)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6), dpi=100,
                             gridspec_kw={"width_ratios": [1.1, 1.4, 1.0]})

    # 3D-panel stand-in: terrain triangles seen from above (floors only), paths and goal.
    ax = axes[0]
    tri = log["/terrain"][0][1]["entities"][0]["triangles"][0]
    pts = np.array([[p["x"], p["y"], p["z"]] for p in tri["points"]])
    faces = pts[np.array(tri["indices"]).reshape(-1, 3)]
    normal = np.cross(faces[:, 1] - faces[:, 0], faces[:, 2] - faces[:, 0])
    up = normal[:, 2] > 1e-9
    faces = faces[up]
    order = np.argsort(faces[:, :, 2].mean(1))
    z = faces[order, :, 2].mean(1)
    coll = PolyCollection(faces[order, :, :2], array=z, cmap="Greys_r", edgecolors="face",
                          linewidths=0.2)
    ax.add_collection(coll)
    fig.colorbar(coll, ax=ax, label="terrain z (m)", fraction=0.046)
    seen = []
    robots = sorted({int(t.split("/")[1][5:]) for t in log if t.startswith("/robot")
                     and t.split("/")[1][5:].isdigit()})
    for i in robots:
        xy = []
        for _, m in log["/tf"]:
            t = next(t for t in m["transforms"] if t["child_frame_id"] == f"robot{i}/base")
            xy.append((t["translation"]["x"], t["translation"]["y"]))
        xy = np.array(xy)
        seen.append(xy)
        done = np.array([m["done"] for _, m in log[f"/robot{i}/status"]])
        cut = np.insert(xy, np.nonzero(done)[0], np.nan, axis=0)  # no line across a reset
        ax.plot(cut[:, 0], cut[:, 1], lw=1.5, label=f"robot{i} base path")
        ax.plot(*xy[0], "o", ms=4, color=ax.lines[-1].get_color())
    g = log["/robot0/goal"][-1][1]["pose"]["position"]
    ax.plot(g["x"], g["y"], "r*", ms=14, label="goal")
    seen = np.concatenate(seen + [np.array([[g["x"], g["y"]]])])
    centre = 0.5 * (seen.min(0) + seen.max(0))
    half = 0.5 * np.max(seen.max(0) - seen.min(0)) + 1.5  # the robots' surroundings
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("/terrain, /tf (base), /robot0/goal")
    ax.legend(fontsize=7, loc="lower right")

    # Plot panel: reward terms of robot 0 (the largest five by mean magnitude, and the total).
    ax = axes[1]
    rewards = log["/robot0/reward"]
    t = np.array([ts for ts, _ in rewards]) * 1e-9
    terms = [k for k in rewards[0][1] if k not in ("timestamp", "total")]
    series = {k: np.array([m[k] for _, m in rewards]) for k in terms}
    top = sorted(terms, key=lambda k: -np.abs(series[k]).mean())[:5]
    for k in top:
        ax.plot(t, series[k], lw=1.2, label=f".{k}")
    ax.plot(t, [m["total"] for _, m in rewards], "k", lw=1.8, label=".total")
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("reward per step")
    ax.set_title("/robot0/reward")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)

    # Plot panel: joint angles of the front-left leg.
    ax = axes[2]
    joints = log["/robot0/joint_states"]
    t = np.array([ts for ts, _ in joints]) * 1e-9
    names = joints[0][1]["name"]
    for j, name in enumerate(names[:3]):
        ax.plot(t, [m["position"][j] for _, m in joints], lw=1.2, label=f".position[{j}] {name}")
    contact = np.array([m["FL"] for _, m in log["/robot0/foot_contacts"]], float)
    lo, hi = ax.get_ylim()
    ax.fill_between(t, lo, lo + 0.06 * (hi - lo) * contact * 1.0, step="mid", color="tab:green",
                    alpha=0.5, label="/robot0/foot_contacts.FL")
    ax.set_ylim(lo, hi)
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("rad")
    ax.set_title("/robot0/joint_states (FL leg)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)

    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    with atomic_path(out) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--checkpoint", default=None, help="policy.npz (default: a fresh policy)")
    p.add_argument("--family", default="u_shaped")
    p.add_argument("--level", type=int, default=2, help="1-based test level")
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--seconds", type=float, default=4.0)
    p.add_argument("--frame-s", type=float, default=1.0, help="time of the rendered frame")
    p.add_argument("--resolution", type=float, default=0.025)
    p.add_argument("--out", default=str(HERE), help="folder for the two PNGs")
    args = p.parse_args(argv)

    from PIL import Image

    from mjx_stairs.rl.policy import load_policy
    from mjx_stairs.tools import mcap_log

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        checkpoint = args.checkpoint
        if checkpoint is None:
            checkpoint = Path(tmp) / "fresh_policy.npz"
            fresh_policy(checkpoint)
        policy = load_policy(checkpoint)
        it = policy.metadata.get("iteration", 0)
        who = "untrained policy (trainer init)" if args.checkpoint is None else \
            f"{Path(args.checkpoint).parent.name} policy, iteration {it}"
        spec = play.PlaySpec(family=args.family, level=args.level - 1, robots=args.robots,
                             seconds=args.seconds, resolution=args.resolution)
        env = play.make_play_env(policy, spec)
        r = play.rollout(policy, spec, env)
        print(play.summary(r))

        k = min(r.num_frames - 1, max(0, int(round(args.frame_s / r.dt)) - 1))
        (frame,) = play.render_frames(env.robot.mj_model, r.qpos[k:k + 1, 0], 640, 480,
                                      goal=r.goal[k, 0])
        png = out / "play_frame.png"
        with atomic_path(png) as tmp_png:
            Image.fromarray(frame).save(tmp_png)
        print(f"wrote {png} (robot 0 at t = {(k + 1) * r.dt:.2f} s, MUJOCO_GL={play.ensure_gl()})")

        mcap_path = Path(tmp) / "rollout.mcap"
        mcap_log.write_mcap(mcap_path, env, r)
        title = (f"MCAP of `mjx-stairs play`, read back: {args.family} test level {args.level}, "
                 f"{args.robots} robots, {args.seconds:g} s, {who}")
        plot_mcap(mcap_path, out / "mcap_plot.png", title)
        print(f"wrote {out / 'mcap_plot.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
