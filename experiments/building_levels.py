"""What the building family trains on: per level of a schedule, the staircases its tiles hold.

Every level of an atlas holds 2 x 11 fixed building staircases (variants_per_family 22 in
experiments/generalist.toml: each shape and turn, seeds 0 and 1), sampled once from
(schedule, level, variant, seed) and shortened to fit the tile. Prints riser, tread, width,
pitch, risers per staircase, how many reach the code suite's risers, and the landings of the
U and switchback staircases, per level (docs/diagnosis_code_suite.md section 2).

    PYTHONPATH=. python experiments/building_levels.py [--schedule train] [--seeds 2]
"""

from __future__ import annotations

import argparse

import numpy as np

from terrains.building import VARIANTS, sample_staircase, variant_seed
from terrains.levels import levels

CODE_RISERS = (0.178, 0.197)  # m: commercial, residential (terrains/suites.toml)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--schedule", default="train")
    ap.add_argument("--seeds", type=int, default=2, help="staircases per variant and level")
    ap.add_argument("--tile-size", type=float, default=10.0)
    ap.add_argument("--resolution", type=float, default=0.025)
    a = ap.parse_args()
    print("| level | riser band (cm) | risers (cm) | treads (m) | widths (m) | pitch (deg, median) "
          "| risers/stair | >= 17.8 cm | >= 19.7 cm | U/switchback landing (m) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for i, lv in enumerate(levels("building", a.schedule)):
        st = [sample_staircase(lv, v, np.random.default_rng(variant_seed(a.schedule, i, v, s)),
                               max_size=a.tile_size, resolution=a.resolution)
              for v in VARIANTS for s in range(a.seeds)]
        r = np.array([s.riser for s in st])
        t = np.array([s.tread for s in st])
        w = np.array([s.width for s in st])
        pitch = np.degrees(np.arctan2(r, t))
        n = np.array([s.risers for s in st])
        land = [s.landing for s in st if s.shape in ("u", "switchback")]
        print(f"| {i + 1} | {100 * lv.riser[0]:.1f}-{100 * lv.riser[1]:.1f} | "
              f"{100 * r.min():.1f}-{100 * r.max():.1f} | {t.min():.2f}-{t.max():.2f} | "
              f"{w.min():.2f}-{w.max():.2f} | {pitch.min():.1f}-{pitch.max():.1f} "
              f"({np.median(pitch):.1f}) | {n.min()}-{n.max()} | "
              + " | ".join(f"{int((r >= c - 1e-9).sum())}/{len(st)}" for c in CODE_RISERS)
              + f" | {min(land):.2f}-{max(land):.2f} |")
    for name, (riser, tread) in (("commercial", (0.178, 0.279)), ("residential", (0.197, 0.254))):
        print(f"code {name}: pitch {np.degrees(np.arctan2(riser, tread)):.1f} deg")


if __name__ == "__main__":
    main()
