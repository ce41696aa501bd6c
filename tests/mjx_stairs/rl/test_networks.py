"""CNN-MLP actor-critic: shapes, pooling semantics, Gaussian helpers, gradient vs finite diffs."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjx_stairs.env.observation import N_VEC  # the stair env's vector part
from mjx_stairs.rl import networks
from mjx_stairs.rl.networks import NetworkConfig, ObsLayout

# jitted once per distinct static config; eager init would compile every op separately
_init = jax.jit(networks.init_params, static_argnums=(1, 2, 3, 4))


def test_param_shapes_for_the_stair_layout():
    cfg = NetworkConfig()
    p = _init(jax.random.PRNGKey(0), cfg, N_VEC, (21, 21), 12)
    shapes = jax.tree_util.tree_map(lambda x: x.shape, p)
    assert [c["w"] for c in shapes["encoder"]["conv"]] == [(3, 3, 1, 8), (3, 3, 8, 16),
                                                           (3, 3, 16, 32)]
    assert shapes["encoder"]["proj"]["w"] == (2 * 2 * 32, 128)
    assert [layer["w"] for layer in shapes["actor"]] == [(177, 128), (128, 128), (128, 64),
                                                         (64, 12)]
    assert [layer["w"] for layer in shapes["critic"]] == [(177, 128), (128, 128), (128, 64),
                                                          (64, 1)]
    np.testing.assert_allclose(jnp.exp(p["log_std"]), np.full(12, 0.8), rtol=1e-6)
    layout = ObsLayout(N_VEC, (21, 21))
    assert layout.obs_size == N_VEC + 441
    obs = jax.ShapeDtypeStruct((3, 5, N_VEC + 441), jnp.float32)
    for fn, shape in ((networks.encode, (3, 5, 177)), (networks.actor_mean, (3, 5, 12)),
                      (networks.value, (3, 5))):
        assert jax.eval_shape(lambda p, o, fn=fn: fn(p, o, layout), p, obs).shape == shape
    assert networks.param_count(p) < 200_000


def test_orthogonal_init_scales():
    p = _init(jax.random.PRNGKey(0), NetworkConfig(), 10, (), 3)
    w0 = np.asarray(p["actor"][0]["w"])  # [10, 128]: orthonormal rows times sqrt 2
    np.testing.assert_allclose(w0 @ w0.T, 2.0 * np.eye(10), atol=1e-4)
    out = np.asarray(p["actor"][-1]["w"])  # [64, 3]: columns of norm 0.01
    np.testing.assert_allclose(np.linalg.norm(out, axis=0), 0.01, rtol=1e-4)
    assert all(float(jnp.abs(layer["b"]).max()) == 0.0 for layer in p["critic"])


def test_no_map_skips_the_encoder():
    p = _init(jax.random.PRNGKey(0), NetworkConfig(), 5, (), 2)
    assert "encoder" not in p and p["actor"][0]["w"].shape == (5, 128)
    obs = jnp.ones((4, 5))
    assert networks.encode(p, obs, ObsLayout(5)) is obs
    assert networks.actor_mean(p, obs, ObsLayout(5)).shape == (4, 2)


def test_the_encoder_sees_the_map_and_the_mlp_sees_the_vec():
    layout = ObsLayout(3, (7, 7))
    p = _init(jax.random.PRNGKey(0), NetworkConfig(), 3, (7, 7), 2)
    obs = jax.random.normal(jax.random.PRNGKey(1), (52,))
    feat = networks.encode(p, obs, layout)
    np.testing.assert_array_equal(feat[128:], obs[:3])  # vec passes through after the latent
    obs2 = obs.at[3 + 7 * 3 + 5].add(1.0)  # change one map cell (row 3, col 5)
    assert not np.allclose(networks.encode(p, obs2, layout)[:128], feat[:128])


def test_adaptive_avg_pool_matches_torch_bins():
    x = jnp.arange(5 * 5, dtype=jnp.float32).reshape(1, 5, 5, 1)
    got = networks._adaptive_avg_pool(x, (2, 2))[0, :, :, 0]
    a = np.arange(25.0).reshape(5, 5)
    # torch AdaptiveAvgPool2d(2) on 5x5: bins [0:3] and [2:5] in each axis (overlapping)
    want = [[a[0:3, 0:3].mean(), a[0:3, 2:5].mean()], [a[2:5, 0:3].mean(), a[2:5, 2:5].mean()]]
    np.testing.assert_allclose(got, want)
    y = networks._maxpool2(jnp.arange(25.0).reshape(1, 5, 5, 1))[0, :, :, 0]
    np.testing.assert_array_equal(y, [[6.0, 8.0], [16.0, 18.0]])


def test_gaussian_helpers():
    mean = jnp.array([[0.0, 1.0], [2.0, -1.0]])
    log_std = jnp.log(jnp.array([0.5, 2.0]))
    a = jnp.array([[0.3, 0.0], [2.0, 3.0]])
    std = np.array([0.5, 2.0])
    want = np.sum(-0.5 * ((np.asarray(a) - np.asarray(mean)) / std) ** 2 - np.log(std)
                  - 0.5 * math.log(2 * math.pi), axis=-1)
    np.testing.assert_allclose(networks.log_prob(mean, log_std, a), want, rtol=1e-6)
    assert float(networks.entropy(log_std)) == pytest.approx(
        float(np.sum(0.5 * np.log(2 * math.pi * math.e * std**2))), rel=1e-6)
    s = networks.sample(jax.random.PRNGKey(0), jnp.zeros((20000, 2)), log_std)
    np.testing.assert_allclose(np.std(np.asarray(s), axis=0), std, rtol=0.03)
    assert float(jnp.abs(networks.gaussian_kl(mean, log_std, mean, log_std)).max()) < 1e-6
    # KL(N(0,1) || N(1,2)) = log 2 + (1 + 1) / 8 - 1/2
    kl = networks.gaussian_kl(jnp.zeros(1), jnp.zeros(1), jnp.ones(1), jnp.log(2.0) * jnp.ones(1))
    assert float(kl) == pytest.approx(math.log(2.0) + 2.0 / 8.0 - 0.5, rel=1e-6)


def test_cnn_mlp_gradient_matches_finite_differences():
    """Directional derivatives of a scalar of actor and critic outputs, in float64."""
    layout = ObsLayout(4, (9, 9))
    cfg = NetworkConfig(conv_channels=(4, 4, 6), latent_size=16, actor_hidden=(16, 8),
                        critic_hidden=(12,))
    with jax.enable_x64(True):
        p = _init(jax.random.PRNGKey(0), cfg, 4, (9, 9), 3)
        p = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float64), p)
        # larger output weights so the actor head matters as much as the critic
        p["actor"][-1]["w"] = p["actor"][-1]["w"] * 100.0
        obs = jax.random.normal(jax.random.PRNGKey(1), (6, 85), jnp.float64)
        act = jax.random.normal(jax.random.PRNGKey(2), (6, 3), jnp.float64)

        def loss(params):
            mean = networks.actor_mean(params, obs, layout)
            lp = networks.log_prob(mean, params["log_std"], act)
            v = networks.value(params, obs, layout)
            return jnp.sum(lp * jnp.arange(6.0)) + jnp.sum(jnp.sin(v))

        eps = 1e-6

        loss_jit = jax.jit(loss)
        grad = jax.jit(jax.grad(loss))(p)
        g_leaves, treedef = jax.tree_util.tree_flatten(grad)
        leaves = jax.tree_util.tree_leaves(p)
        rng = np.random.default_rng(0)
        for i in range(4):
            d = [rng.normal(size=x.shape) for x in leaves]
            plus = treedef.unflatten([x + eps * y for x, y in zip(leaves, d, strict=True)])
            minus = treedef.unflatten([x - eps * y for x, y in zip(leaves, d, strict=True)])
            fd = (float(loss_jit(plus)) - float(loss_jit(minus))) / (2 * eps)
            an = sum(float(np.vdot(np.asarray(a), b)) for a, b in zip(g_leaves, d, strict=True))
            assert abs(fd - an) <= 1e-6 * max(1.0, abs(an)), (i, fd, an)
        g = grad
        # every parameter group, the encoder included, receives gradient
        for name in ("encoder", "actor", "critic", "log_std"):
            assert float(sum(jnp.abs(x).sum() for x in jax.tree_util.tree_leaves(g[name]))) > 0


def test_fused_actor_critic_equals_separate_passes():
    layout = ObsLayout(N_VEC, (21, 21))
    p = _init(jax.random.PRNGKey(3), NetworkConfig(), N_VEC, (21, 21), 12)
    k1, k2 = jax.random.split(jax.random.PRNGKey(4))
    obs = jax.random.normal(k1, (7, N_VEC + 441))
    critic_obs = jax.random.normal(k2, (7, N_VEC + 441))
    mean, value = jax.jit(networks.actor_critic, static_argnums=3)(p, obs, critic_obs, layout)
    np.testing.assert_allclose(mean, jax.jit(networks.actor_mean, static_argnums=2)(
        p, obs, layout), atol=1e-5)
    np.testing.assert_allclose(value, jax.jit(networks.value, static_argnums=2)(
        p, critic_obs, layout), atol=1e-5)

    def fused(p):
        m, v = networks.actor_critic(p, obs, critic_obs, layout)
        return jnp.sum(m**2) + jnp.sum(v)

    def separate(p):
        return jnp.sum(networks.actor_mean(p, obs, layout) ** 2) + jnp.sum(
            networks.value(p, critic_obs, layout))

    ga, gb = jax.jit(jax.grad(fused))(p), jax.jit(jax.grad(separate))(p)
    for a, b in zip(jax.tree_util.tree_leaves(ga), jax.tree_util.tree_leaves(gb), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5)


def _encoder_grads(cfg, n_vec, map_shape, n_obs, init_seed, data_seed, bump=None):
    """Params (random non-zero biases, so their gradients and the padding's interplay are
    tested) and a jitted ``grad(params, impl) -> (grads, features)`` of a fixed scalar loss of
    the encoder's features on random maps, or on flat maps of 0.3 with one 1.0 at map index
    ``bump`` of the first robot (every max-pool window away from it ties)."""
    layout = ObsLayout(n_vec, map_shape)
    p = _init(jax.random.PRNGKey(init_seed), cfg, n_vec, map_shape, 2)
    k = jax.random.split(jax.random.PRNGKey(data_seed), 4)
    p["encoder"]["conv"] = [{"w": c["w"], "b": 0.3 * jax.random.normal(kk, c["b"].shape)}
                            for c, kk in zip(p["encoder"]["conv"], k[:3], strict=True)]
    obs = jax.random.normal(k[3], (n_obs, layout.obs_size))
    if bump is not None:
        obs = obs.at[:, n_vec:].set(0.3).at[0, n_vec + bump].set(1.0)
    weights = jnp.cos(jnp.arange(cfg.latent_size + n_vec, dtype=jnp.float32))

    def loss(params, impl):
        feat = networks.encode(params, obs, layout, conv_impl=impl)
        return jnp.sum(jnp.sin(feat) * weights), feat

    return p, jax.jit(jax.grad(loss, has_aux=True), static_argnums=1)


@pytest.mark.parametrize("n_vec,map_shape,flat", [(N_VEC, (21, 21), False), (3, (7, 9), False),
                                                  (N_VEC, (21, 21), True), (2, (10, 8), False)])
def test_fused_conv_encoder_equals_xla_encoder(n_vec, map_shape, flat):
    """conv_impl='fused' (the conv stack with its written-out backward pass) is the same
    function as lax.conv: features and their gradients wrt every
    encoder param agree. Flat maps (one bump) make the max-pool windows tie: the gradient is
    split between the tied positions as jax's max gradient does."""
    cfg = NetworkConfig(conv_channels=(4, 6, 8), latent_size=16, actor_hidden=(8,),
                        critic_hidden=(8,))
    p, grad = _encoder_grads(cfg, n_vec, map_shape, 5, 5, 6, bump=30 if flat else None)
    (ga, fa), (gb, fb) = grad(p, "xla"), grad(p, "fused")
    np.testing.assert_allclose(fb, fa, rtol=1e-5, atol=1e-5)
    assert float(jnp.abs(fa[:, :16]).max()) > 0.0
    for a, b in zip(jax.tree_util.tree_leaves(ga["encoder"]),
                    jax.tree_util.tree_leaves(gb["encoder"]), strict=True):
        assert float(jnp.abs(a).max()) > 0.0
        np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("flat", [False, True])
def test_fused_bf16_encoder_is_close_to_float32(flat):
    """conv_impl='fused_bf16' stores the stack's activations and pre-pool gradients in
    bfloat16 (float32 accumulation): features and every encoder gradient close to, not equal
    to, lax.conv in float32 (relative norm of the difference); its matmuls take bfloat16
    operands."""
    cfg = NetworkConfig(latent_size=16, actor_hidden=(8,), critic_hidden=(8,))
    p, grad = _encoder_grads(cfg, 3, (21, 21), 6, 7, 9, bump=37 if flat else None)
    (ga, fa), (gb, fb) = grad(p, "xla"), grad(p, "fused_bf16")
    assert fb.dtype == jnp.float32
    err = float(jnp.abs(fb - fa).max() / jnp.abs(fa).max())
    assert 0.0 < err < 3e-2, err
    for a, b in zip(jax.tree_util.tree_leaves(ga["encoder"]),
                    jax.tree_util.tree_leaves(gb["encoder"]), strict=True):
        assert b.dtype == jnp.float32
        # a few per cent: besides the rounding, a pooling window whose top two values are
        # within bfloat16's resolution may route its gradient to the other one
        gerr = float(jnp.linalg.norm(b - a) / jnp.linalg.norm(a))
        assert gerr < 6e-2, gerr
    jaxpr = str(jax.make_jaxpr(lambda q: grad(q, "fused_bf16"))(p))
    assert "bf16" in jaxpr and "preferred_element_type=bfloat16" in jaxpr


def test_auto_conv_impl_picks_by_backend():
    assert NetworkConfig().conv_impl == "auto"
    want = networks.CONV_IMPLS["fused" if jax.default_backend() == "gpu" else "xla"]
    assert networks._conv_fn("auto") is want


def test_unknown_conv_impl_is_a_one_line_error():
    with pytest.raises(ValueError, match=r"network\.conv_impl.*'cudnn'.*'xla'.*'fused'.*'auto'"):
        networks.encode({}, jnp.zeros((2, 3)), ObsLayout(3), conv_impl="cudnn")
    with pytest.raises(ValueError, match=r"network\.conv_impl.*'cudnn'"):
        networks.init_params(jax.random.PRNGKey(0), NetworkConfig(conv_impl="cudnn"), 3, (), 2)
