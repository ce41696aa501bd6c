"""Settings of the CPU test session (what `make test` runs). The suite's time goes into XLA
compiling MJX programs, so:

- XLA compiles at backend (LLVM) optimisation level 0 unless XLA_FLAGS already names a level:
  a compile takes half the time and the compiled program runs ~3x slower, which the few hundred
  steps a test takes do not notice. The HLO passes are the same, so are the functions computed.
- A compilation cache for the session, in a temporary folder removed at its end (shared by
  pytest-xdist's workers): a program built again from equal inputs (the same env config and
  atlas, the same policy) is compiled once. Nothing is kept between sessions, so every run
  compiles what it tests.
"""

from __future__ import annotations

import os
import shutil
import tempfile

_FLAGS = {"--xla_backend_optimization_level": "0", "--xla_cpu_use_fusion_emitters": "false"}
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
