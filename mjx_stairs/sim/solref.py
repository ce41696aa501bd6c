"""The contact's stiffness in a MuJoCo spec, one place for MJX's model (sim.robot), the ground
truth's box world (sim.box_world) and sim2sim's world (tools.sim2sim_world). No JAX: sim2sim
imports it."""

from __future__ import annotations

MJCF_TIMECONST_S = 0.02
"""The geoms' solref time constant in assets/go2.xml and go2_full.xml (MuJoCo's default)."""


def set_timeconst(spec, timeconst: float) -> None:
    """Every geom of `spec` (robot and terrain: a contact mixes its two geoms' solref) with the
    solref (timeconst, 1), critically damped; 0 leaves the MJCF's (MJCF_TIMECONST_S). Call it
    after the last geom is added (RobotConfig.contact_timeconst, sim2sim --contact-timeconst)."""
    if timeconst:
        for geom in spec.geoms:
            geom.solref = [timeconst, 1.0]
