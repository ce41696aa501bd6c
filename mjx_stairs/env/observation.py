"""The observation, as one table: the env builds it from this, export writes its sidecar from
it, tests take their sizes from it.

Both streams have the same layout [vector (N_VEC) | height map (size x size, row-major)];
``obs["state"]`` (actor) carries uniform noise per term's group, ``obs["privileged_state"]``
(critic) is the same without noise. Every entry is in the SI unit given (scale 1: the policy's
normaliser does all scaling).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from mjx_stairs.env.config import HeightMapConfig, NoiseConfig, leg_damping


class ObsTerm(NamedTuple):
    """One named range of the observation vector."""

    name: str
    size: int
    unit: str
    noise: str | None  # the NoiseConfig field of its training noise (None: no noise)
    scale: float  # multiplies the value (1: SI units)
    description: str


VECTOR = (
    ObsTerm("base_lin_vel", 3, "m/s", "lin_vel", 1.0,
            "base linear velocity in the base (body) frame"),
    ObsTerm("base_ang_vel", 3, "rad/s", "ang_vel", 1.0,
            "base angular velocity in the base frame (IMU gyro)"),
    ObsTerm("projected_gravity", 3, "1", "gravity", 1.0,
            "unit gravity vector (0, 0, -1) in the base frame"),
    ObsTerm("joint_pos", 12, "rad", "joint_pos", 1.0,
            "joint positions minus the nominal pose, joint_names order"),
    ObsTerm("joint_vel", 12, "rad/s", "joint_vel", 1.0, "joint velocities, joint_names order"),
    ObsTerm("last_action", 12, "1", None, 1.0,
            "the previous policy action, clipped to +-action_clip"),
    ObsTerm("goal", 4, "m, m, m, rad", None, 1.0,
            "goal position minus base position in the base frame (x, y, z), then the yaw error "
            "goal_yaw - base_yaw wrapped to [-pi, pi)"),
)
"""The vector part, in order."""

N_VEC = sum(t.size for t in VECTOR)
"""Length of the vector part of an observation without history (before the height map)."""


def history_terms(history: int) -> tuple[ObsTerm, ...]:
    """The terms of `env.obs_history` policy steps of history (none at 0), after "goal": what a
    policy needs to tell robots apart that one frame cannot (a long action delay from a short
    one, docs/deploy.md)."""
    if history <= 0:
        return ()
    return (
        ObsTerm("joint_pos_history", 12 * history, "rad", "joint_pos", 1.0,
                f"joint positions minus the nominal pose at the {history} previous policy "
                "steps (what the joint_pos term of each earlier observation measured), newest "
                "first, joint_names order within each step; the reset pose before the "
                "episode's first"),
        ObsTerm("action_history", 12 * history, "1", None, 1.0,
                f"the {history} policy actions before last_action, newest first, clipped to "
                "+-action_clip (zeros before the episode's first)"),
    )


def history_start(history: int, joint_pos: jnp.ndarray) -> dict[str, jnp.ndarray]:
    """The env info's history keys (none at `history` 0) at an episode's start with the joints
    at `joint_pos` (minus the nominal pose): that pose at every earlier step, no earlier
    actions."""
    if not history:
        return {}
    return {"joint_pos_history": jnp.tile(joint_pos, (history, 1)),
            "action_history": jnp.zeros((history, 12))}


def shift_in(history: jnp.ndarray, newest: jnp.ndarray) -> jnp.ndarray:
    """[..., H, n] history with `newest` [..., n] in front and the oldest row dropped."""
    return jnp.concatenate([newest[..., None, :], history[..., :-1, :]], axis=-2)


DELAY_SCALE = 50.0
"""1 / s: the action delay term reads 1 at 20 ms (one policy step), the most training draws."""

DELAY_TERM = ObsTerm(
    "action_delay", 1, "s", None, DELAY_SCALE,
    "the action delay: from the moment the observation is measured to the moment the PD target "
    "computed from it takes effect at the motors (a robot program measures its own once); value "
    f"= {DELAY_SCALE:g} * delay_s, 1 at 20 ms")
"""With env.obs_action_delay, after the history terms."""

DAMPING_TERM = ObsTerm(
    "joint_damping", 1, "N m s/rad", None, 1.0,
    "the leg joints' passive damping (training's drawn or set value)")
"""With env.obs_joint_damping, after the delay term: a privileged input of the critic."""


def vector_terms(history: int = 0, delay: bool = False,
                 damping: bool = False) -> tuple[ObsTerm, ...]:
    """The vector part, in order, with `history` steps of history, then with `delay` the action
    delay and with `damping` the joints' damping."""
    return (*VECTOR, *history_terms(history), *((DELAY_TERM,) if delay else ()),
            *((DAMPING_TERM,) if damping else ()))


def n_vec(history: int = 0, delay: bool = False, damping: bool = False) -> int:
    """Length of the vector part with `history` steps of history (and the delay, damping)."""
    return sum(t.size for t in vector_terms(history, delay, damping))


def slices(terms: tuple[ObsTerm, ...]) -> dict[str, slice]:
    """{term name: its slice of the observation} for `terms` laid out in order."""
    out, at = {}, 0
    for t in terms:
        out[t.name], at = slice(at, at + t.size), at + t.size
    return out


def height_map_term(hm: HeightMapConfig) -> ObsTerm:
    return ObsTerm("height_map", hm.size * hm.size, "m", "height", 1.0,
                   f"{hm.size} x {hm.size} heights, row-major (rows along the base's yaw-frame "
                   f"y, columns along its x); value = clip(base_z - terrain_z - {hm.offset}, "
                   f"-{hm.clip}, {hm.clip})")


def terms(hm: HeightMapConfig, history: int = 0, delay: bool = False,
          damping: bool = False) -> tuple[ObsTerm, ...]:
    """Every term of an observation, in order."""
    return (*vector_terms(history, delay, damping), height_map_term(hm))


def size(hm: HeightMapConfig, history: int = 0, delay: bool = False,
         damping: bool = False) -> int:
    """Floats per observation."""
    return n_vec(history, delay, damping) + hm.size * hm.size


def of_config(config) -> tuple[ObsTerm, ...]:
    """Every term of the observation an env of this EnvConfig builds."""
    return terms(config.height_map, config.obs_history, config.obs_action_delay,
                 config.obs_joint_damping)


def vector_of(config) -> tuple[ObsTerm, ...]:
    """The vector part of the observation an env of this EnvConfig builds, in order."""
    return vector_terms(config.obs_history, config.obs_action_delay, config.obs_joint_damping)


def n_vec_of(config) -> int:
    """Length of the vector part of the observation an env of this EnvConfig builds."""
    return n_vec(config.obs_history, config.obs_action_delay, config.obs_joint_damping)


def critic_only(config) -> tuple[str, ...]:
    """The terms of an env config's observation that the actor reads as 0 (the critic alone
    reads them): the action delay with env.obs_action_delay_actor false, the joints' damping."""
    return (*(() if config.obs_action_delay_actor else (DELAY_TERM.name,)),
            *((DAMPING_TERM.name,) if config.obs_joint_damping else ()))


def robot_values(config, info: dict) -> dict[str, jnp.ndarray]:
    """The robot's own terms that an env config observes, from its reset draws in `info`: the
    action delay (whole physics steps, in s) and the joints' damping (where not drawn, the
    robot's: config.leg_damping)."""
    out = {}
    if config.obs_action_delay:
        steps = info.get("delay_steps", jnp.zeros((), jnp.int32))
        out[DELAY_TERM.name] = (steps * config.robot.timestep).astype(jnp.float32)[None]
    if config.obs_joint_damping:
        out[DAMPING_TERM.name] = jnp.asarray(info.get("joint_damping", leg_damping(config.robot)),
                                             jnp.float32).reshape(1)
    return out


def assemble(values: dict[str, jnp.ndarray], table: tuple[ObsTerm, ...], noise: NoiseConfig,
             rng: jax.Array | None, critic_only: tuple[str, ...] = ()) -> dict[str, jnp.ndarray]:
    """{"state", "privileged_state"} [size] from {term name: [term size]} laid out as `table`
    (terms, of_config); with ``rng`` None or the noise off both are clean. ``critic_only``:
    terms the actor reads as 0."""
    clean = jnp.concatenate([values[t.name] if t.scale == 1.0 else t.scale * values[t.name]
                             for t in table])
    actor = clean
    if noise.enabled and rng is not None:
        widths = jnp.concatenate([jnp.full((t.size,), getattr(noise, t.noise) if t.noise
                                           else 0.0) for t in table])
        actor = clean + widths * jax.random.uniform(rng, clean.shape, minval=-1.0, maxval=1.0)
    at = slices(table)
    for name in critic_only:
        actor = actor.at[at[name]].set(0.0)
    return {"state": actor, "privileged_state": clean}
