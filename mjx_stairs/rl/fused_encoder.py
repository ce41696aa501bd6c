"""The encoder's conv stack as one function with a hand-written backward pass (conv_impl "fused").

Same function as the per-layer paths in ``networks`` (3x3 SAME conv -> ELU -> 2x2 max-pool for
every layer but the last, conv -> ELU for the last), computed with fewer passes over memory:

- Each conv is one row-Toeplitz matmul (``toeplitz``):
  the three neighbouring input rows side by side, [N, rows, 3 W Cin], times a [3 W Cin, cols]
  matrix built from the kernel. A pooled layer computes only the rows and columns its floor
  pooling keeps, and orders the output columns by column parity, (parity, col // 2, cout), so that
  the 2x2 max is a max over four contiguous blocks of the [N, H/2, 2, 2, W/2 Cout] result.
- Pooling comes before the ELU and the bias: both are monotone in each position and the bias
  is the same within a window, so max(ELU(z + b)) = ELU(max(z) + b), with a quarter of the
  ELU work.
- The backward pass is written out: per layer one elementwise pass (ELU derivative, the pooling
  gradient routed to the window's maxima, split equally between ties as jax's max gradient
  does), one matmul for the weights (the bias gradient rides in it as a column of ones on the
  input rows, padded with zeros to an aligned width) and one for the input. Forward saves the
  row stacks, the ELU outputs and a byte per pooled value saying which of its four positions
  held the max (computed in the same pass as the max).

Params are those of ``networks`` (the kernels [3, 3, Cin, Cout] and biases [Cout]); the
Toeplitz matrices are built from them outside the custom VJP, so their gradient folds back into
the kernels by ordinary autodiff.

``dtype`` bfloat16 (conv_impl "fused_bf16") stores what the stack writes to memory in bfloat16:
the row stacks and the matmul operands, the pre-pool conv outputs, the ELU outputs and the
pre-pool gradients. Matmuls accumulate in float32, the ELU and its derivative are computed in
float32, and the weight and bias gradients come out of their matmul in float32. The encoder is
memory-bound at this size, so this halves most of its traffic; it is NOT the same function (the
rounding of every stored value, about 3 significant digits).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

_HIGHEST = jax.lax.Precision.HIGHEST


def _shifts(w_in: int, cols: np.ndarray) -> np.ndarray:
    """0/1 S [3 (kx), w_in (input col), len(cols)]: S[kx, i, j] = 1 where input column
    i = cols[j] + kx - 1 lies inside the row (outside it is SAME padding's zeros)."""
    s = np.zeros((3, w_in, len(cols)), np.float32)
    for j, o in enumerate(cols):
        for kx in range(3):
            i = o + kx - 1
            if 0 <= i < w_in:
                s[kx, i, j] = 1.0
    return s


def _out_cols(w_in: int, pooled: bool) -> np.ndarray:
    """Output columns a layer computes, in matrix order: parity-major when pooled (the columns
    2j, then 2j + 1, for j < w_in // 2; an odd last column is dropped), all of them otherwise."""
    if not pooled:
        return np.arange(w_in)
    half = w_in // 2
    return np.concatenate([2 * np.arange(half), 2 * np.arange(half) + 1])


def toeplitz(kernel: jax.Array, w_in: int, pooled: bool) -> jax.Array:
    """Kernel [3, 3, Cin, Cout] -> T [3 w_in Cin, n_cols Cout], rows (ky, col, cin), columns
    (output col in ``_out_cols`` order, cout). HIGHEST precision: S only selects weights."""
    c_in, c_out = kernel.shape[2], kernel.shape[3]
    cols = _out_cols(w_in, pooled)
    t = jnp.einsum("xio,yxcd->yicod", _shifts(w_in, cols), kernel, precision=_HIGHEST)
    return t.reshape(3 * w_in * c_in, len(cols) * c_out)


def _stack_width(r: int) -> int:
    """Columns of a row stack of rows with r floats: 3 r, the ones column, zeros up to a
    multiple of 16 (an unaligned K, such as 241, sends cuBLAS to kernels ~2x slower)."""
    return -(-(3 * r + 1) // 16) * 16


def _row_stack(x: jax.Array, n_rows: int) -> jax.Array:
    """[N, H, R] -> [N, n_rows, _stack_width(R)]: for output row o, input rows o-1, o, o+1
    (zeros past the edges) side by side, then a 1 (the bias column of the weight gradient),
    then zeros."""
    n, h, r = x.shape
    xp = jnp.pad(x, ((0, 0), (1, max(n_rows + 1 - h, 0)), (0, 0)))
    ones = jnp.ones((n, n_rows, 1), x.dtype)
    zeros = jnp.zeros((n, n_rows, _stack_width(r) - 3 * r - 1), x.dtype)
    return jnp.concatenate(
        [xp[:, :n_rows], xp[:, 1:n_rows + 1], xp[:, 2:n_rows + 2], ones, zeros], axis=-1)


def _row_unstack(g: jax.Array, h: int) -> jax.Array:
    """Adjoint of ``_row_stack`` without its ones column: [N, n_rows, 3 R] -> [N, h, R]."""
    n, n_rows, _ = g.shape
    r = g.shape[-1] // 3
    gp = jnp.zeros((n, max(n_rows + 2, h + 2), r), g.dtype)
    gp = gp.at[:, 0:n_rows].add(g[..., :r])
    gp = gp.at[:, 1:n_rows + 1].add(g[..., r:2 * r])
    gp = gp.at[:, 2:n_rows + 2].add(g[..., 2 * r:3 * r])
    return gp[:, 1:h + 1]


def _elu_grad(a: jax.Array) -> jax.Array:
    """d ELU / d input, from the ELU's output a: 1 where a > 0, else exp(u) = a + 1."""
    return jnp.where(a > 0, 1.0, a + 1.0)


def _matmul(x: jax.Array, t: jax.Array) -> jax.Array:
    """[N, rows, K'] @ T [K, C] with zero rows appended to T for the stack's ones column and
    padding (forward: they contribute nothing; the bias is added exactly, outside the matmul).
    The result has x's dtype (a bfloat16 matmul still accumulates in float32)."""
    t = t.astype(x.dtype)
    t_aug = jnp.concatenate([t, jnp.zeros((x.shape[-1] - t.shape[0], t.shape[1]), t.dtype)])
    return jnp.matmul(x, t_aug, preferred_element_type=x.dtype)


def _pool4(z: jax.Array) -> tuple[jax.Array, jax.Array]:
    """z [N, hp, 2, 2, C] (the four positions of each 2x2 window) -> (their max [N, hp, C], a
    byte [N, hp, C] whose bit 2 q + p says position (q, p) holds it). Elementwise over the four
    slices, so XLA computes both in one pass over z."""
    zs = [z[:, :, q, p] for q in (0, 1) for p in (0, 1)]
    m = jnp.maximum(jnp.maximum(zs[0], zs[1]), jnp.maximum(zs[2], zs[3]))
    bits = sum(((zk == m).astype(jnp.uint8) << k) for k, zk in enumerate(zs))
    return m, bits.astype(jnp.uint8)


def _elu(z: jax.Array, b: jax.Array, dtype) -> jax.Array:
    """ELU(z + b) computed in float32, stored in ``dtype``."""
    return jax.nn.elu(z.astype(jnp.float32) + b).astype(dtype)


def _forward(maps, ts, biases, geom, dtype):
    """maps [N, H, W] -> last layer's ELU output [N, H_L, W_L Cout_L] (float32) and the
    residuals (in ``dtype``)."""
    x = maps.astype(dtype)
    res = []
    n = maps.shape[0]
    for (h, w, c_out, pooled), t, b in zip(geom, ts, biases, strict=True):
        if pooled:
            hp, wp = h // 2, w // 2
            stack = _row_stack(x, 2 * hp)
            m, bits = _pool4(_matmul(stack, t).reshape(n, hp, 2, 2, wp * c_out))
            a = _elu(m, jnp.tile(b, wp), dtype)
            res.append((stack, bits, a))
        else:
            stack = _row_stack(x, h)
            a = _elu(_matmul(stack, t), jnp.tile(b, w), dtype)
            res.append((stack, None, a))
        x = a
    return x.astype(jnp.float32), res


def _backward(geom, res, ts, g):
    """The gradient g of the last layer's output -> (grads of ts, of biases, of the maps), all
    float32. The elementwise work is float32; the pre-pool gradient is stored in the stack's
    dtype, the matmuls accumulate in float32."""
    gts, gbs = [], []
    for (h, w, c_out, pooled), t, (stack, bits, a) in zip(
            reversed(geom), reversed(ts), reversed(res), strict=True):
        n, dtype = stack.shape[0], stack.dtype
        gm = g.astype(jnp.float32) * _elu_grad(a.astype(jnp.float32))
        if pooled:
            hp, wp = h // 2, w // 2
            hit = ((bits[:, :, None] >> jnp.arange(4, dtype=jnp.uint8)[:, None]) & 1).astype(
                jnp.float32)  # [N, hp, 4, wp Cout]
            gz = (gm / jnp.sum(hit, axis=2))[:, :, None] * hit
            gz = gz.reshape(n, 2 * hp, 2 * wp * c_out)
        else:
            gz = gm
        gz = gz.astype(dtype)
        k, rows = stack.shape[-1], t.shape[0]
        gt_aug = jnp.matmul(stack.reshape(-1, k).T, gz.reshape(-1, gz.shape[-1]),
                            preferred_element_type=jnp.float32)
        gts.append(gt_aug[:rows])
        gbs.append(gt_aug[rows].reshape(-1, c_out).sum(axis=0))  # the ones column's row
        g = _row_unstack(jnp.matmul(gz, t.T.astype(dtype), preferred_element_type=jnp.float32), h)
    return gts[::-1], gbs[::-1], g


def geometry(map_shape: tuple[int, int], channels: tuple[int, ...]) -> tuple:
    """Per layer (input rows, input cols, output channels, pooled), for a [H, W] map."""
    h, w = map_shape
    out = []
    for i, c in enumerate(channels):
        pooled = i < len(channels) - 1
        out.append((h, w, c, pooled))
        if pooled:
            h, w = h // 2, w // 2
    return tuple(out)


@functools.lru_cache(maxsize=None)
def _make(geom, dtype):
    """The custom-VJP conv stack for one geometry and storage dtype (static, hashable)."""

    @jax.custom_vjp
    def convs(maps, ts, biases):
        return _forward(maps, ts, biases, geom, dtype)[0]

    def fwd(maps, ts, biases):
        out, res = _forward(maps, ts, biases, geom, dtype)
        return out, (res, ts)

    def bwd(saved, g):
        res, ts = saved
        gts, gbs, gmaps = _backward(geom, res, ts, g)
        return gmaps, gts, gbs

    convs.defvjp(fwd, bwd)
    return convs


def conv_stack(maps: jax.Array, convs: list[dict], dtype=jnp.float32) -> jax.Array:
    """maps [N, H, W] (one input channel) -> [N, H_L, W_L, C_L] float32: every conv layer of
    ``convs`` ([{"w": [3, 3, Cin, Cout], "b": [Cout]}, ...]) with its ELU, 2x2 max-pool after
    all but the last. ``dtype``: what the stack stores (float32, or bfloat16: see the module
    docstring)."""
    channels = tuple(int(p["w"].shape[-1]) for p in convs)
    geom = geometry(tuple(maps.shape[1:]), channels)
    ts = [toeplitz(p["w"], w, pooled) for (_, w, _, pooled), p in zip(geom, convs, strict=True)]
    out = _make(geom, jnp.dtype(dtype))(maps, ts, [p["b"] for p in convs])
    h, w, c, _ = geom[-1]
    return out.reshape(maps.shape[0], h, w, c)
