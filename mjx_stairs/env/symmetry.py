"""The Go2's left-right mirror, as signed permutations of its observation and action, for the
symmetry loss of PPO (`ppo.mirror_loss_coef`; the env hands it to the trainer as `env.mirror`).

A staircase seen in a mirror is a staircase, and the Go2 is left-right symmetric (its mass centre
on the body's x-z plane, go2.xml), so the policy's mean action on a mirrored observation should be
the mirrored action. The mirror reflects the body frame's y axis: vectors (velocity, gravity, the
goal's offset) flip their y component, the angular velocity (a pseudovector) its x and z, the
goal's yaw error its sign; the left and right legs swap (FL <-> FR, RL <-> RR) and the hips'
abduction flips sign (the nominal pose's hips are mirror images: +-0.1 rad); the height map's
rows, along the base's y on a grid centred on the base, reverse. Mirroring twice is the identity.

    m = symmetry.mirror_of(observation.terms(hm, history), hm.size)   # StairEnv.mirror
    mirrored_obs = m.obs.apply(obs)   # [..., D]
    mirrored_act = m.act.apply(act)   # [..., 12]
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax.numpy as jnp
import numpy as np

from mjx_stairs.env import observation

LEGS_MIRRORED = (1, 0, 3, 2)
"""The leg each leg becomes (FL, FR, RL, RR order): FL <-> FR, RL <-> RR."""


class Signed(NamedTuple):
    """A signed permutation: mirrored[..., i] = x[..., index[i]] * sign[i]."""

    index: np.ndarray  # [n] int
    sign: np.ndarray  # [n] float, +-1

    def apply(self, x: jnp.ndarray) -> jnp.ndarray:
        """x [..., n] mirrored: x[..., index] * sign."""
        return jnp.take(x, jnp.asarray(self.index), axis=-1) * jnp.asarray(self.sign, x.dtype)


class Mirror(NamedTuple):
    """The mirror of one observation vector (actor's and critic's layout) and of an action."""

    obs: Signed
    act: Signed


def joints() -> Signed:
    """[12] joints in JOINT_NAMES order (legs FL, FR, RL, RR x hip, thigh, calf): the legs swap,
    the hips flip sign."""
    index = np.array([3 * leg + j for leg in LEGS_MIRRORED for j in range(3)])
    sign = np.tile([-1.0, 1.0, 1.0], 4)
    return Signed(index, sign)


_VECTOR_SIGNS = {  # the vector terms: their own components, signs only
    "base_lin_vel": (1.0, -1.0, 1.0),
    "base_ang_vel": (-1.0, 1.0, -1.0),
    "projected_gravity": (1.0, -1.0, 1.0),
    "goal": (1.0, -1.0, 1.0, -1.0),  # x, y, z in the base frame, then the yaw error
    "action_delay": (1.0,),  # a time: the same in the mirror
    "joint_damping": (1.0,),  # every leg joint's: the same in the mirror
}
_JOINT_TERMS = ("joint_pos", "joint_vel", "last_action", "joint_pos_history", "action_history")


def _height_map(size: int) -> Signed:
    """[size * size] row-major (rows along y on a grid centred on the base): rows reversed."""
    rows = np.arange(size * size).reshape(size, size)[::-1]
    return Signed(rows.reshape(-1), np.ones(size * size))


def _term(name: str, size: int, map_side: int) -> Signed:
    if name in _VECTOR_SIGNS:
        signs = _VECTOR_SIGNS[name]
        if len(signs) != size:
            raise ValueError(f"observation term {name!r} has {size} entries, the mirror knows "
                             f"{len(signs)}")
        return Signed(np.arange(size), np.asarray(signs))
    if name in _JOINT_TERMS:
        if size % 12:
            raise ValueError(f"observation term {name!r} has {size} entries, not 12 per step")
        j = joints()
        steps = np.arange(size // 12)[:, None] * 12
        return Signed((steps + j.index).reshape(-1), np.tile(j.sign, size // 12))
    if name == "height_map":
        if size != map_side * map_side:
            raise ValueError(f"height map term has {size} entries, not {map_side} x {map_side}")
        return _height_map(map_side)
    raise ValueError(f"observation term {name!r} has no left-right mirror: add it to "
                     "mjx_stairs/env/symmetry.py before training with ppo.mirror_loss_coef")


def mirror_of(terms: Sequence, map_side: int) -> Mirror:
    """The mirror of an observation laid out as `terms` (env.observation.terms: name, size, in
    order) and of the 12 joint actions; `map_side` the height map's points per side."""
    index, sign, start = [], [], 0
    for t in terms:
        m = _term(t.name, t.size, map_side)
        index.append(m.index + start)
        sign.append(m.sign)
        start += t.size
    return Mirror(Signed(np.concatenate(index), np.concatenate(sign)), joints())


def of_config(config) -> Mirror:
    """The mirror of the observation an env of this EnvConfig builds (env.observation)."""
    return mirror_of(observation.of_config(config), config.height_map.size)
