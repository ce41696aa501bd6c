"""Actor-critic networks as plain functions on a params pytree (no flax).

Observation layout (both the actor's "state" and the critic's "privileged_state" stream):
``[vec (n_vec floats) | height map (map_h * map_w floats, row-major)]``. With ``map_shape == ()``
there is no map: the encoder is skipped and the MLPs see the whole vector.

Params pytree (dicts and lists of float32 arrays; C = conv_channels, P = pool_size,
L = latent_size, F = L + n_vec with a map, n_vec without):

```
{
  "encoder": {                                   # absent when map_shape == ()
    "conv": [{"w": [3, 3, 1, C0], "b": [C0]},    # conv3x3 SAME -> ELU -> maxpool 2
             {"w": [3, 3, C0, C1], "b": [C1]},   # conv3x3 SAME -> ELU -> maxpool 2
             {"w": [3, 3, C1, C2], "b": [C2]}],  # conv3x3 SAME -> ELU -> adaptive avg pool PxP
    "proj": {"w": [P * P * C2, L], "b": [L]},     # linear -> ELU = latent
  },
  "actor":  [{"w": [F, 128], "b": [128]}, {"w": [128, 128], ...}, {"w": [128, 64], ...},
             {"w": [64, A], "b": [A]}],          # ELU between layers, linear output = mean
  "critic": [... same hidden sizes ..., {"w": [64, 1], "b": [1]}],
  "log_std": [A],                                # state-independent, init log(init_std)
}
```

The encoder is shared: the actor encodes the actor stream, the critic encodes the privileged
stream with the same encoder weights, and both losses train it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any, Literal

import jax
import jax.numpy as jnp

from mjx_stairs.rl import fused_encoder

Params = dict[str, Any]

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class NetworkConfig:
    """Sizes and initialisation of the CNN-MLP actor-critic."""

    conv_channels: tuple[int, ...] = field(
        default=(8, 16, 32), metadata={"help": "output channels of the 3x3 conv layers"}
    )
    pool_size: int = field(
        default=2, metadata={"help": "adaptive average pool output (pool_size x pool_size)"}
    )
    latent_size: int = field(default=128, metadata={"help": "size of the map latent"})
    actor_hidden: tuple[int, ...] = field(
        default=(128, 128, 64), metadata={"help": "actor MLP hidden sizes"}
    )
    critic_hidden: tuple[int, ...] = field(
        default=(128, 128, 64), metadata={"help": "critic MLP hidden sizes"}
    )
    init_std: float = field(default=0.8, metadata={"help": "initial policy std (all actions)"})
    normalize_obs: bool = field(
        default=True, metadata={"help": "running mean/std normalisation of both obs streams"}
    )
    obs_clip: float = field(
        default=10.0, metadata={"help": "clip normalised observations to +-obs_clip (0 = off)"}
    )
    conv_impl: Literal["auto", "xla", "fused", "fused_bf16"] = field(
        default="auto",
        metadata={"help": "how the 3x3 convs are computed, not what: 'xla' (lax.conv), 'fused' "
                  "(the conv stack as one function with a written-out backward pass: 4.65 vs "
                  "10.7 ms fwd+bwd on an H100) or 'auto' (fused on a GPU, xla elsewhere); "
                  "'fused_bf16' stores the fused stack's activations in bfloat16 (3.04 ms; "
                  "float32 accumulation; not the same function; a loaded policy runs in "
                  "float32)"},
    )


@dataclass(frozen=True)
class ObsLayout:
    """Static layout of one observation vector: [vec (n_vec) | map (prod(map_shape))]."""

    n_vec: int
    map_shape: tuple[int, ...] = ()

    @property
    def map_size(self) -> int:
        return math.prod(self.map_shape) if self.map_shape else 0

    @property
    def obs_size(self) -> int:
        return self.n_vec + self.map_size


# ----------------------------------------------------------------------------- init


def _gram_schmidt(a: jax.Array, m: jax.Array) -> jax.Array:
    """Orthonormalise the first ``m`` columns of ``a`` [N, M] (zero-padded rows are harmless,
    columns from ``m`` on come out zero). Classical Gram-Schmidt, applied twice for stability."""
    cols = jnp.arange(a.shape[1])

    def body(j, q):
        qm = q * (cols < j)
        v = a[:, j]
        v = v - qm @ (qm.T @ v)
        v = v - qm @ (qm.T @ v)
        v = jnp.where(j < m, v / jnp.maximum(jnp.linalg.norm(v), 1e-12), 0.0)
        return q.at[:, j].set(v)

    return jax.lax.fori_loop(0, a.shape[1], body, jnp.zeros_like(a))


def _init_weights(rng: jax.Array, specs: list[tuple[int, int, float]]) -> list:
    """Orthogonal weights [n_in, n_out] * gain for each (n_in, n_out, gain).

    One Gaussian draw and one (vmapped) Gram-Schmidt loop for all layers: every separate
    jax.random call or loop costs its own compile on the CPU. Orthonormalises the shorter side
    (same Haar distribution as QR with the sign fix).
    """
    big = max(max(a, b) for a, b, _ in specs)
    small = max(min(a, b) for a, b, _ in specs)
    noise = jax.random.normal(rng, (len(specs), big, small), jnp.float32)
    ms = jnp.array([min(a, b) for a, b, _ in specs])
    rows = jnp.arange(big)[None, :, None]
    ns = jnp.array([max(a, b) for a, b, _ in specs])[:, None, None]
    q = jax.vmap(_gram_schmidt)(jnp.where(rows < ns, noise, 0.0), ms)
    out = []
    for i, (n_in, n_out, gain) in enumerate(specs):
        n, m = max(n_in, n_out), min(n_in, n_out)
        w = q[i, :n, :m] if n_in >= n_out else q[i, :n, :m].T
        out.append(gain * w)
    return out


def _pooled_shape(map_shape: tuple[int, ...], n_conv: int) -> tuple[int, int]:
    h, w = map_shape
    for _ in range(n_conv - 1):
        h, w = h // 2, w // 2
    return h, w


def init_params(
    rng: jax.Array,
    cfg: NetworkConfig,
    n_vec: int,
    map_shape: tuple[int, ...],
    action_size: int,
) -> Params:
    """Fresh actor-critic params; shapes in the module docstring.

    Orthogonal init (rsl_rl / CleanRL style): gain sqrt(2) for hidden layers and convs (as
    [9 C_in, C_out] matrices), 0.01 for the actor output, 1 for the critic output; zero biases.
    """
    _conv_fn(cfg.conv_impl)
    map_shape = tuple(map_shape)
    relu_gain = math.sqrt(2.0)
    specs: list[tuple[int, int, float]] = []
    chans = (1, *cfg.conv_channels)
    if map_shape:
        if len(map_shape) != 2:
            raise ValueError(f"map_shape must be () or (h, w), got {map_shape}")
        h, w = _pooled_shape(map_shape, len(cfg.conv_channels))
        if h < 1 or w < 1:
            raise ValueError(f"map {map_shape} too small for {len(cfg.conv_channels)} conv layers")
        specs += [(9 * c_in, c_out, relu_gain) for c_in, c_out in zip(chans[:-1], chans[1:],
                                                                       strict=True)]
        specs.append((cfg.pool_size * cfg.pool_size * chans[-1], cfg.latent_size, relu_gain))
        n_feat = cfg.latent_size + n_vec
    else:
        n_feat = n_vec
    mlps = {}
    for name, hidden, n_out, out_gain in (("actor", cfg.actor_hidden, action_size, 0.01),
                                          ("critic", cfg.critic_hidden, 1, 1.0)):
        sizes = [n_feat, *hidden, n_out]
        mlps[name] = len(specs)
        specs += [(a, b, out_gain if i == len(sizes) - 2 else relu_gain)
                  for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:], strict=True))]
    ws = _init_weights(rng, specs)

    def dense(i):
        return {"w": ws[i], "b": jnp.zeros((specs[i][1],), jnp.float32)}

    params: Params = {}
    if map_shape:
        n_conv = len(cfg.conv_channels)
        conv = []
        for i, (c_in, c_out) in enumerate(zip(chans[:-1], chans[1:], strict=True)):
            d = dense(i)
            conv.append({"w": d["w"].reshape(3, 3, c_in, c_out), "b": d["b"]})
        params["encoder"] = {"conv": conv, "proj": dense(n_conv)}
    params["actor"] = [dense(i) for i in range(mlps["actor"], mlps["critic"])]
    params["critic"] = [dense(i) for i in range(mlps["critic"], len(specs))]
    params["log_std"] = jnp.full((action_size,), math.log(cfg.init_std), jnp.float32)
    return params


# ----------------------------------------------------------------------------- layers


def _conv3x3(x: jax.Array, p: Params) -> jax.Array:
    """[N, H, W, Cin] -> [N, H, W, Cout], SAME padding, NHWC."""
    y = jax.lax.conv_general_dilated(
        x, p["w"], window_strides=(1, 1), padding="SAME",
        dimension_numbers=("NHWC", "HWIO", "NHWC"),
    )
    return y + p["b"]


def _layer_by_layer(conv):
    """A conv stack from a per-layer conv: maps [N, H, W] -> [N, H_L, W_L, C_L], each layer
    conv -> ELU, a 2x2 max-pool after all but the last."""

    def stack(maps: jax.Array, convs: list[Params]) -> jax.Array:
        x = maps[..., None]
        for i, p in enumerate(convs):
            x = jax.nn.elu(conv(x, p))
            if i < len(convs) - 1:
                x = _maxpool2(x)
        return x

    return stack


# conv_impl -> the conv stack; all compute the same function (the bf16 ones up to rounding)
CONV_IMPLS = {
    "xla": _layer_by_layer(_conv3x3),
    "fused": fused_encoder.conv_stack,  # one custom-VJP function for the whole stack
    # the same, storing its activations, stacks and pre-pool gradients in bfloat16
    "fused_bf16": functools.partial(fused_encoder.conv_stack, dtype=jnp.bfloat16),
}


# conv_impls that round (training-speed settings): a loaded policy is computed in float32
REDUCED_PRECISION_IMPLS = ("fused_bf16",)


def _conv_fn(conv_impl: str):
    if conv_impl == "auto":  # resolved when traced: the backend the function compiles for
        conv_impl = "fused" if jax.default_backend() == "gpu" else "xla"
    try:
        return CONV_IMPLS[conv_impl]
    except (KeyError, TypeError):
        raise ValueError(f"network.conv_impl: unknown conv_impl {conv_impl!r} (expected one of "
                         f"{', '.join(repr(k) for k in (*CONV_IMPLS, 'auto'))})") from None


def _maxpool2(x: jax.Array) -> jax.Array:
    """[N, H, W, C] -> [N, H // 2, W // 2, C] (floor, like torch MaxPool2d(2)).

    A reshape + max rather than reduce_window: its gradient avoids select_and_scatter, which
    made the encoder's backward pass ~20 % slower on an H100."""
    n, h, w, c = x.shape
    h2, w2 = h // 2, w // 2
    return x[:, : 2 * h2, : 2 * w2, :].reshape(n, h2, 2, w2, 2, c).max(axis=(2, 4))


def _adaptive_avg_pool(x: jax.Array, out_hw: tuple[int, int]) -> jax.Array:
    """[N, H, W, C] -> [N, oh, ow, C] with torch AdaptiveAvgPool2d bins (may overlap)."""
    _, h, w, _ = x.shape
    oh, ow = out_hw
    rows = []
    for i in range(oh):
        r0, r1 = (i * h) // oh, -((-(i + 1) * h) // oh)
        cols = []
        for j in range(ow):
            c0, c1 = (j * w) // ow, -((-(j + 1) * w) // ow)
            cols.append(jnp.mean(x[:, r0:r1, c0:c1, :], axis=(1, 2)))
        rows.append(jnp.stack(cols, axis=1))
    return jnp.stack(rows, axis=1)


def _mlp(layers: list[Params], x: jax.Array) -> jax.Array:
    for p in layers[:-1]:
        x = jax.nn.elu(x @ p["w"] + p["b"])
    return x @ layers[-1]["w"] + layers[-1]["b"]


# ----------------------------------------------------------------------------- model


def encode(
    params: Params, obs: jax.Array, layout: ObsLayout, *, conv_impl: str = "auto"
) -> jax.Array:
    """Features for the MLPs: [..., D] -> [..., latent_size + n_vec] (latent || vec).

    Without a map (``layout.map_shape == ()``) the obs is returned unchanged. ``conv_impl``
    (NetworkConfig.conv_impl) picks how the 3x3 convs are computed, not what they compute.
    """
    conv_stack = _conv_fn(conv_impl)
    if not layout.map_shape:
        return obs
    if obs.shape[-1] != layout.obs_size:
        raise ValueError(f"obs has {obs.shape[-1]} floats, layout expects {layout.obs_size}")
    enc = params["encoder"]
    lead = obs.shape[:-1]
    vec = obs[..., : layout.n_vec]
    with jax.named_scope("encoder"):  # names the CNN's kernels in a profiler trace
        x = conv_stack(obs[..., layout.n_vec :].reshape(-1, *layout.map_shape), enc["conv"])
        n_flat = enc["proj"]["w"].shape[0]
        c = x.shape[-1]
        pool_hw = _pool_hw_from(n_flat, c)
        x = _adaptive_avg_pool(x, pool_hw).reshape(x.shape[0], -1)
        latent = jax.nn.elu(x @ enc["proj"]["w"] + enc["proj"]["b"])
    latent = latent.reshape(*lead, -1)
    return jnp.concatenate([latent, vec], axis=-1)


def _pool_hw_from(n_flat: int, channels: int) -> tuple[int, int]:
    cells = n_flat // channels
    side = int(round(math.sqrt(cells)))
    if side * side != cells:
        raise ValueError(f"encoder proj expects {cells} pooled cells, not a square pool")
    return side, side


def actor_mean(
    params: Params, obs: jax.Array, layout: ObsLayout, *, conv_impl: str = "auto"
) -> jax.Array:
    """Policy mean: [..., D] -> [..., A]."""
    return _mlp(params["actor"], encode(params, obs, layout, conv_impl=conv_impl))


def value(
    params: Params, obs: jax.Array, layout: ObsLayout, *, conv_impl: str = "auto"
) -> jax.Array:
    """State value from the privileged stream: [..., D] -> [...]."""
    return _mlp(params["critic"], encode(params, obs, layout, conv_impl=conv_impl))[..., 0]


def actor_critic(
    params: Params, obs: jax.Array, critic_obs: jax.Array, layout: ObsLayout, *,
    conv_impl: str = "auto",
) -> tuple[jax.Array, jax.Array]:
    """(actor_mean(obs), value(critic_obs)) with ONE pass of the shared encoder over both
    streams stacked on the batch axis: [N, D], [N, D] -> [N, A], [N]. The encoder's small
    kernels are launch- and memory-bound, so one call on 2N maps costs less than two on N."""
    n = obs.shape[0]
    feats = encode(params, jnp.concatenate([obs, critic_obs], axis=0), layout,
                   conv_impl=conv_impl)
    return _mlp(params["actor"], feats[:n]), _mlp(params["critic"], feats[n:])[..., 0]


def log_prob(mean: jax.Array, log_std: jax.Array, action: jax.Array) -> jax.Array:
    """Diagonal Gaussian log-density summed over the action axis: [..., A] -> [...]."""
    z = (action - mean) * jnp.exp(-log_std)
    return jnp.sum(-0.5 * z * z - log_std - 0.5 * _LOG_2PI, axis=-1)


def entropy(log_std: jax.Array) -> jax.Array:
    """Entropy of the diagonal Gaussian (state-independent): [A] -> []."""
    return jnp.sum(log_std + 0.5 * (1.0 + _LOG_2PI))


def sample(rng: jax.Array, mean: jax.Array, log_std: jax.Array) -> jax.Array:
    """Draw an action: mean + std * N(0, 1), [..., A]."""
    return mean + jnp.exp(log_std) * jax.random.normal(rng, mean.shape, mean.dtype)


def gaussian_kl(
    mean_old: jax.Array, log_std_old: jax.Array, mean_new: jax.Array, log_std_new: jax.Array
) -> jax.Array:
    """KL(old || new) of diagonal Gaussians, summed over the action axis: [..., A] -> [...]."""
    var_old = jnp.exp(2.0 * log_std_old)
    var_new = jnp.exp(2.0 * log_std_new)
    kl = log_std_new - log_std_old + (var_old + (mean_old - mean_new) ** 2) / (2.0 * var_new) - 0.5
    return jnp.sum(kl, axis=-1)


def param_count(params: Params) -> int:
    return sum(int(x.size) for x in jax.tree_util.tree_leaves(params))
