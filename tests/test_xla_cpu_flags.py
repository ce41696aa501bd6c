"""mjx_stairs/__init__.py's XLA flag: two batched Cholesky factorisations in one CPU program, as
MJX's step has them with the damping integrated implicitly, run to the end (on a 2-core machine
XLA's concurrency-optimised scheduler ran them at once, and they deadlocked from 256 matrices)."""

import os
import subprocess
import sys

PROGRAM = """
import mjx_stairs  # sets XLA_FLAGS before the backend starts
import jax, jax.numpy as jnp, numpy as np
x = np.random.default_rng(0).standard_normal((512, 18, 18)).astype(np.float32)
a = jnp.asarray(x @ x.transpose(0, 2, 1) + 18 * np.eye(18, dtype=np.float32))
def solve(m, b):
    lo = jax.vmap(jax.scipy.linalg.cho_factor)(m)[0]
    return jax.vmap(lambda l, v: jax.scipy.linalg.cho_solve((l, False), v))(lo, b)
def body(c, _):
    x = solve(c, jnp.ones((512, 18))) + solve(c + 0.01 * jnp.eye(18), jnp.ones((512, 18)))
    return c + 1e-4 * jnp.einsum("bi,bj->bij", x, x), None
out = jax.jit(lambda a: jax.lax.scan(body, a, None, length=50)[0])(a)
print(bool(jnp.isfinite(out).all()))
"""


def test_the_package_sets_the_flag_and_two_batched_choleskys_finish():
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["JAX_PLATFORMS"] = "cpu"
    r = subprocess.run([sys.executable, "-c", PROGRAM], env=env, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip().splitlines()[-1] == "True"
    import mjx_stairs  # noqa: F401

    assert "--xla_cpu_enable_concurrency_optimized_scheduler=false" in os.environ["XLA_FLAGS"]
