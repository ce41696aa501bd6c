"""A tiny continuous-control task for the trainer tests, following the stair env's contract.

2-D point mass reaching a goal. Unbatched brax Env: ``reset(rng)``, ``step(state, action)``
with the auto-reset inside ``step``; obs dict {"state" (noisy), "privileged_state"}; truncation
by timeout; termination when the point leaves the arena; ``info["final_obs"]`` holds the obs
before the auto-reset; metrics ``reward/<term>``, ``success``, ``level``.

With ``map_shape=(h, w)`` the observation also carries an h x w "height map": a bump centred on
the goal, sampled on a grid around the point (so the CNN encoder sees goal information).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import Env, State


class PointReach(Env):
    """obs vec = [goal - pos (2), vel (2), time left fraction (1)]; action = force [2]."""

    def __init__(
        self,
        episode_length: int = 40,
        map_shape: tuple[int, ...] = (),
        obs_noise: float = 0.01,
        dt: float = 0.1,
        told: int = 0,
    ):
        self.episode_length = episode_length
        self.map_shape = tuple(map_shape)
        self.obs_noise = obs_noise
        self.dt = dt
        # inputs after the vector part's five, one value per episode in [0.25, 0.75] (as
        # env.obs_action_delay gives each robot's drawn delay)
        self.told = told
        self.n_vec = 5 + told

    # --- brax Env interface -------------------------------------------------------------
    @property
    def observation_size(self):
        d = self.n_vec + (self.map_shape[0] * self.map_shape[1] if self.map_shape else 0)
        return {"state": (d,), "privileged_state": (d,)}

    @property
    def action_size(self) -> int:
        return 2

    @property
    def backend(self) -> str:
        return "jnp"

    def reset(self, rng: jax.Array) -> State:
        rng, k_init = jax.random.split(rng)
        phys = self._sample(k_init)
        rng, k_obs = jax.random.split(rng)
        obs = self._obs(phys, k_obs)
        zero = jnp.zeros(())
        info = {
            "rng": rng,
            "phys": phys,
            "truncation": zero,
            "final_obs": obs,
        }
        metrics = {"reward/dist": zero, "reward/action": zero, "success": zero,
                   "level": zero}
        return State(pipeline_state=None, obs=obs, reward=zero, done=zero,
                     metrics=metrics, info=info)

    def step(self, state: State, action: jax.Array) -> State:
        phys = state.info["phys"]
        force = jnp.clip(action, -1.0, 1.0)
        vel = 0.8 * phys["vel"] + self.dt * 4.0 * force
        pos = phys["pos"] + self.dt * vel
        t = phys["t"] + 1.0
        phys = dict(phys, pos=pos, vel=vel, t=t)
        dist = jnp.linalg.norm(phys["goal"] - pos)
        r_dist = 1.0 - jnp.tanh(dist / 0.5)
        r_action = -0.01 * jnp.sum(jnp.square(force))
        reward = r_dist + r_action
        terminated = (jnp.max(jnp.abs(pos)) > 2.0).astype(jnp.float32)
        truncated = (t >= self.episode_length).astype(jnp.float32) * (1.0 - terminated)
        done = jnp.maximum(terminated, truncated)

        rng, k_obs, k_reset, k_obs2 = jax.random.split(state.info["rng"], 4)
        final_obs = self._obs(phys, k_obs)
        fresh = self._sample(k_reset)
        phys_next = jax.tree_util.tree_map(lambda a, b: jnp.where(done > 0, a, b), fresh, phys)
        obs = jax.tree_util.tree_map(
            lambda a, b: jnp.where(done > 0, a, b), self._obs(phys_next, k_obs2), final_obs
        )
        success = (dist < 0.1).astype(jnp.float32)
        info = dict(state.info, rng=rng, phys=phys_next, truncation=truncated,
                    final_obs=final_obs)
        metrics = {"reward/dist": r_dist, "reward/action": r_action, "success": success,
                   "level": jnp.linalg.norm(phys["goal"])}
        return state.replace(obs=obs, reward=reward, done=done, metrics=metrics, info=info)

    # --- compact checkpoints (same contract as the stair env) ------------------------------
    def pack_state(self, state: State) -> dict:
        """Drop what can be recomputed: the clean obs and final_obs."""
        info = {k: v for k, v in state.info.items() if k != "final_obs"}
        return {"obs": state.obs["state"], "reward": state.reward, "done": state.done,
                "metrics": state.metrics, "info": info}

    def unpack_state(self, packed: dict) -> State:
        info = dict(packed["info"])
        clean = self._obs(info["phys"], jax.random.PRNGKey(0))["privileged_state"]
        obs = {"state": packed["obs"], "privileged_state": clean}
        info["final_obs"] = obs
        return State(pipeline_state=None, obs=obs, reward=packed["reward"], done=packed["done"],
                     metrics=dict(packed["metrics"]), info=info)

    # --- internals ----------------------------------------------------------------------
    def _sample(self, rng: jax.Array) -> dict:
        k1, k2 = jax.random.split(rng)
        return {
            "pos": jax.random.uniform(k1, (2,), minval=-1.0, maxval=1.0),
            "vel": jnp.zeros((2,)),
            "goal": jax.random.uniform(k2, (2,), minval=-1.0, maxval=1.0),
            "t": jnp.zeros(()),
        }

    def _obs(self, phys: dict, rng: jax.Array) -> dict:
        rel = phys["goal"] - phys["pos"]
        time_left = 1.0 - phys["t"] / self.episode_length
        told = jnp.full((self.told,), 0.5 + 0.125 * (phys["goal"][0] + phys["pos"][0]))
        vec = jnp.concatenate([rel, phys["vel"], time_left[None], told])
        if self.map_shape:
            h, w = self.map_shape
            ys = jnp.linspace(-1.0, 1.0, h)
            xs = jnp.linspace(-1.0, 1.0, w)
            gy, gx = jnp.meshgrid(ys, xs, indexing="ij")
            bump = jnp.exp(-((gx - rel[0]) ** 2 + (gy - rel[1]) ** 2) / 0.3)
            clean = jnp.concatenate([vec, bump.reshape(-1)])
        else:
            clean = vec
        noisy = clean + self.obs_noise * jax.random.uniform(
            rng, clean.shape, minval=-1.0, maxval=1.0
        )
        return {"state": noisy, "privileged_state": clean}
