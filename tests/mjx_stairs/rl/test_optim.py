"""Adam, global-norm clipping, the adaptive lr rule and the running normaliser by hand."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from mjx_stairs.rl import normalizer, optim


def test_adam_two_steps_match_hand_computation():
    params = {"a": jnp.array([1.0, -2.0]), "b": [jnp.array(0.5)]}
    g1 = {"a": jnp.array([0.1, -0.3]), "b": [jnp.array(2.0)]}
    g2 = {"a": jnp.array([-0.2, 0.4]), "b": [jnp.array(-1.0)]}
    lr, b1, b2, eps = 0.01, 0.9, 0.999, 1e-8
    state = optim.adam_init(params, lr)
    p1, state = optim.adam_update(g1, state, params, b1, b2, eps)
    p2, state = optim.adam_update(g2, state, p1, b1, b2, eps)

    def hand(p, gs):
        m = v = 0.0
        for t, g in enumerate(gs, start=1):
            m = b1 * m + (1 - b1) * g
            v = b2 * v + (1 - b2) * g * g
            p = p - lr * (m / (1 - b1**t)) / (np.sqrt(v / (1 - b2**t)) + eps)
        return p

    np.testing.assert_allclose(p2["a"], hand(np.array([1.0, -2.0]), [np.array([0.1, -0.3]),
                                                                    np.array([-0.2, 0.4])]),
                               rtol=1e-6)
    np.testing.assert_allclose(p2["b"][0], hand(0.5, [2.0, -1.0]), rtol=1e-6)
    # the first step of Adam moves every coordinate by lr * sign(g)
    np.testing.assert_allclose(p1["a"], [1.0 - lr, -2.0 + lr], rtol=1e-6)
    assert int(state.count) == 2 and float(state.lr) == pytest.approx(lr)


def test_clip_by_global_norm():
    g = {"a": jnp.array([3.0, 0.0]), "b": jnp.array([[4.0]])}  # norm 5
    clipped, norm = optim.clip_by_global_norm(g, 1.0)
    assert float(norm) == pytest.approx(5.0)
    np.testing.assert_allclose(clipped["a"], [0.6, 0.0], rtol=1e-5)
    np.testing.assert_allclose(clipped["b"], [[0.8]], rtol=1e-5)
    assert float(optim.global_norm(clipped)) == pytest.approx(1.0, rel=1e-5)
    same, _ = optim.clip_by_global_norm(g, 10.0)
    np.testing.assert_array_equal(same["a"], g["a"])
    off, _ = optim.clip_by_global_norm(g, 0.0)
    np.testing.assert_array_equal(off["b"], g["b"])


def test_adam_with_clipping_hand_step():
    params = {"w": jnp.array([0.0, 0.0])}
    grads = {"w": jnp.array([30.0, -40.0])}  # norm 50 -> scaled to [0.6, -0.8]
    clipped, _ = optim.clip_by_global_norm(grads, 1.0)
    state = optim.adam_init(params, 0.1)
    state = state._replace(mu={"w": jnp.array([1.0, 1.0])}, nu={"w": jnp.array([0.5, 0.5])},
                           count=jnp.asarray(3, jnp.int32))
    new, st = optim.adam_update(clipped, state, params)
    g = np.array([0.6, -0.8])
    m = 0.9 * 1.0 + 0.1 * g
    v = 0.999 * 0.5 + 0.001 * g * g
    want = -0.1 * (m / (1 - 0.9**4)) / (np.sqrt(v / (1 - 0.999**4)) + 1e-8)
    np.testing.assert_allclose(new["w"], want, rtol=1e-5)
    assert int(st.count) == 4


@pytest.mark.parametrize(
    "lr, kl, want",
    [
        (1e-3, 0.05, 1e-3 / 1.5),   # kl > 2 target
        (1e-3, 0.021, 1e-3 / 1.5),
        (1e-3, 0.02, 1e-3),         # inside the band
        (1e-3, 0.01, 1e-3),
        (1e-3, 0.004, 1.5e-3),      # kl < target / 2
        (1e-3, 0.0, 1e-3),          # kl == 0 (first minibatch): unchanged, like rsl_rl
        (1e-2, 0.001, 1e-2),        # upper bound
        (1.2e-5, 1.0, 1e-5),        # lower bound
    ],
)
def test_adaptive_lr_rule(lr, kl, want):
    got = optim.adapt_lr(jnp.float32(lr), jnp.float32(kl), 0.01)
    assert float(got) == pytest.approx(want, rel=1e-5)


def test_running_stats_merge_equals_numpy():
    rng = np.random.default_rng(0)
    chunks = [rng.normal(3.0, 2.0, size=(n, 4)).astype(np.float32) for n in (5, 17, 1, 40)]
    chunks[1] = chunks[1].reshape(17, 1, 4)  # leading dims are flattened
    stats = normalizer.init_stats(4)
    np.testing.assert_array_equal(normalizer.std(stats), np.ones(4))
    for c in chunks:
        stats = normalizer.update_stats(stats, jnp.asarray(c))
    allx = np.concatenate([c.reshape(-1, 4) for c in chunks])
    assert float(stats.count) == len(allx)
    np.testing.assert_allclose(stats.mean, allx.mean(0), rtol=1e-5)
    np.testing.assert_allclose(normalizer.std(stats), allx.std(0), rtol=1e-4)
    x = jnp.asarray(allx[:3])
    want = (allx[:3] - allx.mean(0)) / (allx.std(0) + normalizer.STD_EPS)
    np.testing.assert_allclose(normalizer.normalize(stats, x), want, rtol=1e-4, atol=1e-5)
    big = normalizer.normalize(stats, jnp.full((1, 4), 1e4), clip=5.0)
    np.testing.assert_array_equal(big, np.full((1, 4), 5.0))
