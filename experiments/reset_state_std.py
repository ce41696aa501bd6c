"""A training state with its exploration std reset, to be resumed (issue 24, docs/results.md 8q):
`init_from_std` starts a run from a policy file, so its curriculum starts over at level 0; this
keeps everything else of the state (curriculum levels, optimiser, env states, RNG, iteration) and
sets every action's std to STD. The observation buffer is zeroed as run.sh's states are.

  python experiments/reset_state_std.py SRC_STATE.npz DST_STATE.npz --std 0.5
"""

from __future__ import annotations

import argparse
import math

from mjx_stairs.rl.checkpoint import compact, load_metadata

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("src")
ap.add_argument("dst")
ap.add_argument("--std", type=float, required=True)
a = ap.parse_args()
if not a.std > 0:
    raise SystemExit(f"--std must be > 0, got {a.std}")
compact(a.src, a.dst, zero=(".env_state['obs']",), set_to={".params['log_std']": math.log(a.std)})
print(f"{a.dst}: iteration {load_metadata(a.dst)['iteration']}, std {a.std} on every action")
