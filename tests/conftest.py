"""Settings of the CPU test session (what `make test` runs). Most of the suite's time is XLA
compiling MJX programs that then run a few hundred steps, so:

- XLA compiles at backend (LLVM) optimisation level 0 with the CPU fusion emitters off, unless
  XLA_FLAGS already names either flag. Measured on a 2-core CPU for the stair env's step: ~6 s
  of CPU to compile instead of ~33 s at XLA's defaults (level 0 alone: ~17 s). Programs run
  slower (the env step ~4x, a PPO update with the conv encoder ~10x), which the tests' short
  rollouts do not notice; the tests that train are sized for it. Same HLO passes, so the same
  functions are computed; float rounding may differ, as between any two backends. (Both flags
  exist in the pinned jaxlib; XLA aborts on a flag it does not know.)
- A compilation cache for the session, in a temporary folder removed at its end (shared by
  pytest-xdist's workers): a program built again from equal inputs (the same env config and
  atlas, the same policy) is compiled once. Nothing is kept between sessions, so every run
  compiles what it tests.

Subprocesses that set XLA_FLAGS themselves (forced host devices) start from the session's.
"""

from __future__ import annotations

import os
import shutil
import tempfile

_FLAGS = {"--xla_backend_optimization_level": "0", "--xla_cpu_use_fusion_emitters": "false",
          # mjx_stairs/__init__.py says why (two batched Cholesky calls at once deadlock)
          "--xla_cpu_enable_concurrency_optimized_scheduler": "false"}
for _flag, _value in _FLAGS.items():
    if _flag not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_flag}={_value}".strip()

import jax  # noqa: E402  (after XLA_FLAGS: the backend reads them when it starts)

_CACHE_VAR = "MJX_STAIRS_TEST_XLA_CACHE"
_OWNER = _CACHE_VAR not in os.environ  # the first process; xdist's workers inherit the folder
if _OWNER:
    os.environ[_CACHE_VAR] = tempfile.mkdtemp(prefix="mjx_stairs_tests_xla_")
jax.config.update("jax_compilation_cache_dir", os.environ[_CACHE_VAR])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


def pytest_unconfigure(config):
    if _OWNER:
        shutil.rmtree(os.environ.pop(_CACHE_VAR), ignore_errors=True)
