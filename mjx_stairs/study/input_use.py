"""How much a policy reads each input: the action's change when one observation term moves.

A term appended to a trained policy (the action delay, the history) starts with zero weights and
may stay nearly unread however long it trains; its first-layer row and what it does to the
action tell. For each vector term of a policy file, over `samples` synthetic observations drawn
from the policy's own normaliser (each input at its running mean plus its std times a standard
normal draw, so every input is where training saw it):

- `row_norm`: the root mean square over the term's inputs of the norm of each input's row of the
  first actor layer (the height map goes through the encoder first and has none);
- `d_action_1std`: the mean absolute change of the action (every joint, policy units) when every
  input of the term moves up by one of its stds, the same step in the normalised units the
  network sees for every term;
- for the action delay, `d_action_0_to_20ms`: the same when the delay goes from 0 to 20 ms;
- `critic_row_norm`, `d_value_1std`: the same two for the critic's first layer and its value,
  over draws from the critic's own normaliser (a term the critic alone reads, the actor's input
  0 there, is read in these columns alone).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from mjx_stairs.env import observation
from mjx_stairs.env.config import env_config_from
from mjx_stairs.rl.policy import (
    Policy,
    normaliser_constants,
    policy_action,
    policy_value,
    saved_config,
)


def term_slices(policy: Policy) -> dict[str, slice]:
    """{term name: its slice of the actor observation} from the env config saved in the policy
    file; the height map as one term."""
    out = observation.slices(observation.vector_of(env_config_from(saved_config(policy, "env"))))
    at = max(sl.stop for sl in out.values())
    if at != policy.layout.n_vec:
        raise ValueError(f"the policy's saved env config gives {at} vector inputs, its layout "
                         f"{policy.layout.n_vec}: not a policy file of this version")
    if policy.layout.map_size:
        out["height_map"] = slice(at, at + policy.layout.map_size)
    return out


def _draws(policy: Policy, stream: str, samples: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(`samples` observations of one stream, each input at its running mean plus its std times
    a standard normal draw; that std [D])."""
    constants = normaliser_constants(policy, stream)
    if constants is None:
        raise ValueError("input_use draws observations from the policy's normaliser; this "
                         "policy does not normalise its observations")
    mean, std = (np.asarray(c, np.float64) for c in constants[:2])  # std: + STD_EPS
    return mean + std * np.random.default_rng(seed).standard_normal((samples, mean.size)), std


def _reads(policy: Policy, head: str, fn, obs: np.ndarray, std: np.ndarray) -> dict:
    """{term: (first-layer row norm of `head`, mean abs change of fn's output at term + 1 std)}
    with the change from 0 to 20 ms for the action delay under "0_to_20ms"."""
    out_of = jax.jit(jax.vmap(fn))

    def output_with(sl: slice | None = None, value=None) -> np.ndarray:
        o = obs.copy()
        if sl is not None:
            o[:, sl] = value
        return np.asarray(out_of(jnp.asarray(o, jnp.float32)))

    def mean_abs(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.abs(a - b).mean())

    base = output_with()
    first = np.asarray(policy.params[head][0]["w"])
    latent = first.shape[0] - policy.layout.n_vec  # rows: [encoder latent | vec]
    out = {}
    for name, sl in term_slices(policy).items():
        rows = first[latent + sl.start:latent + sl.stop]
        row = (float(np.linalg.norm(rows) / np.sqrt(len(rows))) if name != "height_map"
               else float("nan"))
        out[name] = {"row": row, "1std": mean_abs(output_with(sl, obs[:, sl] + std[sl]), base)}
        if name == observation.DELAY_TERM.name:
            out[name]["0_to_20ms"] = mean_abs(output_with(sl, observation.DELAY_SCALE * 0.02),
                                              output_with(sl, 0.0))
    return out


def input_use(policy: Policy, samples: int = 512, seed: int = 0) -> dict[str, dict[str, float]]:
    """{term: {"row_norm", "d_action_1std", "critic_row_norm", "d_value_1std"[,
    "d_action_0_to_20ms"]}} (module docstring); the critic's from its own stream's normaliser,
    so a term the critic alone reads (the actor's input 0 there) shows in its columns alone."""
    actor = _reads(policy, "actor", lambda o: policy_action(policy, o),
                   *_draws(policy, "state", samples, seed))
    critic = _reads(policy, "critic", lambda o: policy_value(policy, o),
                    *_draws(policy, "privileged_state", samples, seed))
    out = {}
    for name, a in actor.items():
        out[name] = {"row_norm": a["row"], "d_action_1std": a["1std"],
                     "critic_row_norm": critic[name]["row"], "d_value_1std": critic[name]["1std"]}
        if "0_to_20ms" in a:
            out[name]["d_action_0_to_20ms"] = a["0_to_20ms"]
    return out


def markdown(use: dict[str, dict[str, float]]) -> str:
    """The table of input_use's result."""
    lines = ["| term | first-layer row norm (rms per input) | mean abs action change, term + 1 "
             "std | critic's first-layer row norm | mean abs value change, term + 1 std |",
             "|---|---|---|---|---|"]
    for name, u in use.items():
        row, crow = ("-" if np.isnan(u[k]) else f"{u[k]:.3f}" for k in ("row_norm",
                                                                          "critic_row_norm"))
        lines.append(f"| {name} | {row} | {u['d_action_1std']:.4f} | {crow} | "
                     f"{u['d_value_1std']:.4f} |")
    for name, u in use.items():
        if "d_action_0_to_20ms" in u:
            lines.append(f"\n{name} from 0 to 20 ms: mean abs action change "
                         f"{u['d_action_0_to_20ms']:.4f}")
    return "\n".join(lines)
