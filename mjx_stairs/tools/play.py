"""Watch a policy: a short rollout of a few robots on one family and level, as a video and as an
MCAP log for Foxglove (written by mjx_stairs.tools.mcap_log).

The rollout uses the evaluation env (no observation noise, no randomisation, no trunk-contact
ending) and the policy's mean action, on an atlas of ONE tile (the family's first variant at that
level) with its flat border, so the heightfield stays small enough to render on a CPU. All robots
start on that tile's spawn area (each with its own random spawn x, y, yaw). Episodes that end
inside the rollout (a fall, or the episode timeout) auto-reset as in training; `done` marks them.

Recorded frame k is the state after policy step k + 1, at sim time (k + 1) * dt.

Rendering: mujoco.Renderer (OpenGL) with the MJCF's tracking camera "track" on robot 0, from the
recorded qpos through mj_forward. On Linux, MUJOCO_GL is set to "egl" when it is unset and
mujoco is not imported yet; `ensure_gl()` then checks that an offscreen context really opens and
falls back to "osmesa" and "glfw". EGL works on an NVIDIA GPU and, through Mesa's llvmpipe, on a
CPU-only machine (software rasterisation, ~0.3 s per frame for a 10 m tile at 2.5 cm).
"""

from __future__ import annotations

import os
import sys

if sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ and (
    "mujoco" not in sys.modules
):
    os.environ["MUJOCO_GL"] = "egl"  # must precede the first `import mujoco`

import dataclasses  # noqa: E402
import importlib  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from mjx_stairs.atomic import atomic_path  # noqa: E402
from mjx_stairs.env.stair_env import StairEnv  # noqa: E402
from mjx_stairs.rl.policy import Policy, load_policy, policy_action  # noqa: E402
from mjx_stairs.study.evaluate import eval_env  # noqa: E402
from mjx_stairs.tools.specs import PlaySpec  # noqa: E402


class RenderError(RuntimeError):
    """No OpenGL context could be opened, or the video could not be written."""


@dataclasses.dataclass
class Rollout:
    """A recorded rollout. T = frames (policy steps), B = robots; numpy arrays.

    qpos [T, B, 19], qvel [T, B, 18], torque [T, B, 12] (last physics substep), action [T, B, 12]
    (the policy output that led to the frame, clipped as the env applies it), obs [T, B, D] (the
    noise-free observation of the frame), reward [T, B], terms {name: [T, B]} (weighted, per
    step), done / terminated / success [T, B] float, foot_contact [T, B, 4] bool (FL, FR, RL, RR),
    tile [T, B] int, goal [T, B, 4] (x, y, z, yaw; world), step [T, B] int (steps into the
    episode after the frame; 0 right after an auto-reset); case_name: the staircase, when it is
    a case (a mesh) rather than a family level.
    """

    spec: PlaySpec
    dt: float
    qpos: np.ndarray
    qvel: np.ndarray
    torque: np.ndarray
    action: np.ndarray
    obs: np.ndarray
    reward: np.ndarray
    terms: dict[str, np.ndarray]
    done: np.ndarray
    terminated: np.ndarray
    success: np.ndarray
    foot_contact: np.ndarray
    tile: np.ndarray
    goal: np.ndarray
    step: np.ndarray
    case_name: str = ""

    @property
    def num_frames(self) -> int:
        return int(self.qpos.shape[0])

    @property
    def num_robots(self) -> int:
        return int(self.qpos.shape[1])

    def terrain_name(self) -> str:
        """The staircase: the case's name, or the family, schedule and level."""
        s = self.spec
        return self.case_name or f"{s.family} {s.schedule} level {s.level + 1}"

    def times(self) -> np.ndarray:
        """[T] sim time (s) of each frame."""
        return (np.arange(self.num_frames) + 1) * self.dt


# ----------------------------------------------------------------------------- rollout


def check_spec(spec: PlaySpec) -> None:
    """ValueError (one line) for an unknown family/schedule, a level out of range, bad sizes."""
    import terrains

    table = terrains.levels(spec.family, spec.schedule)  # unknown family / schedule -> ValueError
    if not 0 <= spec.level < len(table):
        raise ValueError(
            f"level {spec.level + 1} out of range: {spec.family} has {len(table)} "
            f"{spec.schedule} levels (1..{len(table)})"
        )
    if spec.robots < 1:
        raise ValueError(f"robots must be >= 1, got {spec.robots}")
    if not spec.seconds > 0:
        raise ValueError(f"seconds must be > 0, got {spec.seconds}")


def make_play_env(policy: Policy, spec: PlaySpec, case: tuple[str, Any] | None = None
                  ) -> StairEnv:
    """The evaluation env of the policy on an atlas of one tile: `spec.family` at `spec.level`,
    or the (name, terrains.Tile) `case` (e.g. an imported mesh) when given."""
    import terrains

    if case is None:
        check_spec(spec)
        atlas = terrains.build_atlas([spec.family], spec.schedule, [spec.level], 1,
                                     spec.resolution, spec.tile_size, spec.border)
    else:
        atlas = terrains.build_tile_atlas([[case[1]]], spec.border)
    env = eval_env(policy, atlas, spec)  # the evaluation env, decided where eval decides it
    n = env.observation_size["state"][0]
    if policy.layout.obs_size != n or tuple(policy.layout.map_shape) != env.map_shape:
        raise ValueError(
            f"policy observation layout ({policy.layout.obs_size} floats, map "
            f"{tuple(policy.layout.map_shape)}) does not fit the env ({n} floats, map "
            f"{env.map_shape})"
        )
    return env


def rollout(policy: Policy, spec: PlaySpec, env: StairEnv | None = None) -> Rollout:
    """Run `spec.robots` robots for `spec.seconds` with the policy's mean action; record frames."""
    env = make_play_env(policy, spec) if env is None else env
    T = max(1, int(round(spec.seconds / env.dt)))
    B = spec.robots
    keys = jax.random.split(jax.random.PRNGKey(spec.seed), B)
    zeros = jnp.zeros(B, jnp.int32)
    state = jax.jit(jax.vmap(env.reset_at))(keys, zeros, zeros)
    clip = env.config.action_clip
    goals = env.tiles.goal

    def body(st, _):
        action = policy_action(policy, st.obs["state"])
        st = jax.vmap(env.step)(st, action)
        rec = {
            "qpos": st.pipeline_state.qpos,
            "qvel": st.pipeline_state.qvel,
            "torque": st.pipeline_state.ctrl,
            "action": jnp.clip(action, -clip, clip),
            "obs": st.obs["privileged_state"],
            "reward": st.reward,
            "terms": {k[len("reward/"):]: v for k, v in st.metrics.items()
                      if k.startswith("reward/")},
            "done": st.done,
            "terminated": st.metrics["terminated"],
            "success": st.metrics["episode_success"],
            "foot_contact": st.info["last_foot_contact"],
            "tile": st.info["tile"],
            "goal": goals[st.info["tile"]],
            "step": st.info["step"],
        }
        return st, rec

    run = jax.jit(lambda s: jax.lax.scan(body, s, None, length=T)[1])
    rec = jax.device_get(run(state))
    rec = jax.tree_util.tree_map(np.asarray, rec)
    return Rollout(spec=spec, dt=float(env.dt), **rec)


def summary(r: Rollout) -> str:
    """A few lines about the rollout: per robot the distance to the goal at the end, episodes."""
    lines = [
        f"{r.terrain_name()}: {r.num_robots} robots, "
        f"{r.num_frames} steps of {r.dt * 1000:.0f} ms ({r.num_frames * r.dt:.1f} s)"
    ]
    for b in range(r.num_robots):
        pos, goal = r.qpos[-1, b, :3], r.goal[-1, b]
        dist = float(np.linalg.norm(goal[:2] - pos[:2]))
        ends = int(r.done[:, b].sum())
        falls = int(r.terminated[:, b].sum())
        succ = int((r.success[:, b] > 0).sum())
        lines.append(
            f"  robot {b}: goal distance at the end {dist:.2f} m, episodes ended {ends} "
            f"(falls {falls}, successes {succ}), return {r.reward[:, b].sum():.3f}"
        )
    return "\n".join(lines)


# ----------------------------------------------------------------------------- rendering

_GL_BACKEND: str | None = None


def ensure_gl() -> str:
    """Make sure mujoco.Renderer can open an offscreen OpenGL context; returns the backend name.

    Tries MUJOCO_GL if set, then egl, osmesa, glfw (Linux), re-selecting mujoco's GL context
    module for each; raises RenderError naming what failed.
    """
    global _GL_BACKEND
    if _GL_BACKEND is not None:
        return _GL_BACKEND
    from mujoco.rendering.classic import gl_context

    requested = os.environ.get("MUJOCO_GL", "").lower().strip()
    order = [requested] if requested else []
    candidates = ("egl", "osmesa", "glfw") if sys.platform.startswith("linux") else ("",)
    order += [b for b in candidates if b not in order]
    errors = []
    for backend in order:
        if backend:
            os.environ["MUJOCO_GL"] = backend
        try:
            if getattr(gl_context, "_MUJOCO_GL", None) != backend:
                importlib.reload(gl_context)
            ctx = gl_context.GLContext(8, 8)
            ctx.make_current()
            ctx.free()
        except Exception as e:  # any failure means: try the next backend
            errors.append(f"{backend or 'default'}: {type(e).__name__}: {str(e).splitlines()[0]}")
            continue
        _GL_BACKEND = backend or "default"
        return _GL_BACKEND
    raise RenderError(
        "no OpenGL context for offscreen rendering (" + "; ".join(errors) + "); install EGL "
        "(libegl1 + a Mesa or NVIDIA driver) or OSMesa (libosmesa6), or set MUJOCO_GL"
    )


def render_frames(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    width: int = 640,
    height: int = 480,
    camera: str = "track",
    goal: np.ndarray | None = None,
) -> np.ndarray:
    """Render qpos [N, nq] with `camera` -> [N, height, width, 3] uint8 (mj_forward per frame).

    `goal` [N, 4] or [4] (x, y, z, yaw) draws a red marker at the goal.
    """
    ensure_gl()
    model = _with_offscreen(model, width, height)
    data = mujoco.MjData(model)
    qpos = np.asarray(qpos, np.float64).reshape(-1, model.nq)
    goals = None if goal is None else np.broadcast_to(np.asarray(goal, np.float64),
                                                      (len(qpos), 4))
    out = np.empty((len(qpos), height, width, 3), np.uint8)
    with mujoco.Renderer(model, height, width) as renderer:
        for i, q in enumerate(qpos):
            data.qpos[:] = q
            data.qvel[:] = 0.0
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=camera)
            if goals is not None:
                _add_marker(renderer.scene, goals[i, :3] + [0.0, 0.0, 0.05])
            out[i] = renderer.render()
    return out


def _with_offscreen(model: mujoco.MjModel, width: int, height: int) -> mujoco.MjModel:
    """The model, copied with a larger offscreen buffer if (width, height) does not fit."""
    if model.vis.global_.offwidth >= width and model.vis.global_.offheight >= height:
        return model
    import copy

    model = copy.copy(model)
    model.vis.global_.offwidth = max(width, model.vis.global_.offwidth)
    model.vis.global_.offheight = max(height, model.vis.global_.offheight)
    return model


def _add_marker(scene: mujoco.MjvScene, pos: np.ndarray) -> None:
    if scene.ngeom >= scene.maxgeom:
        return
    mujoco.mjv_initGeom(
        scene.geoms[scene.ngeom],
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=np.array([0.08, 0.0, 0.0]),
        pos=np.asarray(pos, np.float64),
        mat=np.eye(3).ravel(),
        rgba=np.array([0.9, 0.15, 0.1, 1.0], np.float32),
    )
    scene.ngeom += 1


def write_video(frames: np.ndarray, path: str | os.PathLike, fps: float) -> None:
    """frames [N, H, W, 3] uint8 -> H.264 mp4 at `fps` (imageio-ffmpeg), written atomically."""
    try:
        import imageio.v2 as imageio
    except ImportError:  # pragma: no cover - a dependency of the package
        raise RenderError("writing a video needs imageio and imageio-ffmpeg "
                          "(pip install imageio imageio-ffmpeg)") from None
    path = Path(path)
    with atomic_path(path, suffix=path.suffix or ".mp4") as tmp, warnings.catch_warnings():
        # ffmpeg runs as a subprocess (fork + exec at once): JAX's fork warning does not apply
        warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called")
        with imageio.get_writer(
            tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264", quality=7,
            pixelformat="yuv420p", macro_block_size=2, ffmpeg_log_level="error",
        ) as w:
            for f in frames:
                w.append_data(f)


def render_video(
    env: StairEnv,
    r: Rollout,
    path: str | os.PathLike,
    robot: int = 0,
    width: int = 640,
    height: int = 480,
    fps: float = 50.0,
) -> int:
    """Render robot `robot` of the rollout with the tracking camera to an mp4; returns frames.

    The control rate is 1 / dt (50 Hz); `fps` below it subsamples frames (every round(rate /
    fps)-th), so the video plays in real time.
    """
    if width % 2 or height % 2 or width < 16 or height < 16:
        raise ValueError(f"video size must be even and at least 16 x 16, got {width} x {height}")
    if not 0 < fps <= 1.0 / r.dt + 1e-6:
        raise ValueError(f"fps must be in (0, {1.0 / r.dt:g}], got {fps}")
    stride = max(1, int(round(1.0 / (r.dt * fps))))
    idx = np.arange(0, r.num_frames, stride)
    frames = render_frames(env.robot.mj_model, r.qpos[idx, robot], width, height,
                           goal=r.goal[idx, robot])
    write_video(frames, path, 1.0 / (r.dt * stride))
    return len(idx)


# ----------------------------------------------------------------------------- the command


def play(
    checkpoint: str | os.PathLike,
    spec: PlaySpec,
    video: str | os.PathLike | None = None,
    mcap: str | os.PathLike | None = None,
    width: int = 640,
    height: int = 480,
    fps: float = 50.0,
    case: tuple[str, Any] | None = None,
) -> dict[str, Any]:
    """Load the policy, roll out on the family level of `spec` or on the (name, tile) `case`,
    write the video and/or the MCAP; returns what was done."""
    if case is None:
        check_spec(spec)
    if video is not None:  # fail before the rollout, not after
        if width % 2 or height % 2 or width < 16 or height < 16:
            raise ValueError(f"video size must be even and >= 16 x 16, got {width} x {height}")
        ensure_gl()
    policy = load_policy(checkpoint)
    env = make_play_env(policy, spec, case)
    t0 = time.time()
    r = rollout(policy, spec, env)
    if case is not None:
        r = dataclasses.replace(r, case_name=case[0])
    out: dict[str, Any] = {"rollout": r, "env": env, "rollout_s": time.time() - t0}
    print(summary(r), flush=True)
    if mcap is not None:
        from mjx_stairs.tools import mcap_log

        t0 = time.time()
        counts = mcap_log.write_mcap(mcap, env, r, policy_meta=_policy_facts(policy, checkpoint))
        out["mcap_counts"] = counts
        print(f"wrote {mcap} ({sum(counts.values())} messages on {len(counts)} topics, "
              f"{time.time() - t0:.1f} s)", flush=True)
    if video is not None:
        t0 = time.time()
        n = render_video(env, r, video, 0, width, height, fps)
        out["video_frames"] = n
        print(f"wrote {video} ({n} frames {width}x{height}, robot 0, MUJOCO_GL={ensure_gl()}, "
              f"{time.time() - t0:.1f} s)", flush=True)
    return out


def _policy_facts(policy: Policy, checkpoint: str | os.PathLike) -> dict[str, str]:
    meta = policy.metadata
    return {
        "checkpoint": str(checkpoint),
        "iteration": str(meta.get("iteration", "")),
        "env_steps": str(meta.get("env_steps", "")),
    }
