"""Perturbed routes (env.route, issue 24): per episode, the route the waypoint follows is the
tile's centre-line as a building map might give it: resampled to a coarse polyline, its corners
cut, shifted sideways by up to a fraction of the stair's clear width. Rewards, success and the
curriculum keep the true centre-line and goal; the final goal the waypoint ends on is the true
one. Off by default (env.route.perturb_prob = 0): then the episode holds no route and the
waypoint is read off the tile's centre-line as before.

Every route keeps the centre-line's K points ([K, 3]); a robot's is in info["route"] with its
arc lengths in info["route_cum"] [K].
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from mjx_stairs.env.config import EnvConfig, RouteConfig
from mjx_stairs.env.tiles import TileTables

TAPER_M = 1.0
"""m: the sideways shift fades to nothing over the route's last metre (it ends on the goal)."""


def active(config: EnvConfig) -> bool:
    return config.route.perturb_prob > 0 and config.goal_mode == "waypoint"


def arc_lengths(route: jnp.ndarray) -> jnp.ndarray:
    """[K] planar arc length at each point of route [K, 3]."""
    seg = jnp.linalg.norm(jnp.diff(route[:, :2], axis=0), axis=-1)
    return jnp.concatenate([jnp.zeros(1, route.dtype), jnp.cumsum(seg)])


def point_at(route: jnp.ndarray, cum: jnp.ndarray, s: jnp.ndarray) -> jnp.ndarray:
    """[M, 3] the points of route [K, 3] (arc lengths cum [K]) at arc lengths s [M]."""
    i = jnp.clip(jnp.searchsorted(cum, s, side="right") - 1, 0, cum.shape[0] - 2)
    t = jnp.clip((s - cum[i]) / jnp.maximum(cum[i + 1] - cum[i], 1e-6), 0.0, 1.0)
    return route[i] + t[:, None] * (route[i + 1] - route[i])


def coarse(route: jnp.ndarray, cum: jnp.ndarray, n: jnp.ndarray) -> jnp.ndarray:
    """[K, 3] the polyline through n (traced) points of route, evenly spaced by arc length,
    resampled at K evenly spaced arc lengths."""
    total, k = cum[-1], route.shape[0]
    jf = jnp.linspace(0.0, 1.0, k) * (n - 1)
    j = jnp.clip(jnp.floor(jf), 0, n - 2)
    a = point_at(route, cum, total * j / (n - 1))
    b = point_at(route, cum, total * (j + 1) / (n - 1))
    return a + (jf - j)[:, None] * (b - a)


def cut_corners(route: jnp.ndarray, span: jnp.ndarray, amount: jnp.ndarray) -> jnp.ndarray:
    """[K, 3] every point moved ``amount`` (0..1) of the way to the midpoint of the points
    ``span`` m before and after it along the route (less near the ends, which stay): a corner
    is cut on its inside, a straight stretch stays."""
    cum = arc_lengths(route)
    reach = jnp.minimum(span, jnp.minimum(cum, cum[-1] - cum))
    middle = 0.5 * (point_at(route, cum, cum - reach) + point_at(route, cum, cum + reach))
    return route + amount * (middle - route)


def shift_sideways(route: jnp.ndarray, offset: jnp.ndarray) -> jnp.ndarray:
    """[K, 3] route moved ``offset`` m to its left (negative: right), fading out over the last
    TAPER_M m. On the inside of a turn the points nearer the corner than the shift would come
    out in a loop that runs backwards (2026-11-27: a U's centre-line shifted a third of its
    width inside looped back ~0.5 m at both landing corners); a shifted point that lies closer
    to the route than its shift is such a loop's, and takes the last good point before it, so
    the route runs from there straight to the first good point after (about the corner's
    mitre)."""
    cum = arc_lengths(route)
    k = route.shape[0]
    idx = jnp.arange(k)
    tangent = route[jnp.minimum(idx + 1, k - 1), :2] - route[jnp.maximum(idx - 1, 0), :2]
    tangent = tangent / jnp.maximum(jnp.linalg.norm(tangent, axis=-1, keepdims=True), 1e-6)
    left = jnp.stack([-tangent[:, 1], tangent[:, 0]], -1)
    shift = offset * jnp.clip((cum[-1] - cum) / TAPER_M, 0.0, 1.0)
    shifted = route.at[:, :2].add(shift[:, None] * left)
    a, ab = route[:-1, :2], route[1:, :2] - route[:-1, :2]  # the route's segments
    p = shifted[:, None, :2]
    t = jnp.clip(jnp.sum((p - a) * ab, -1) / jnp.maximum(jnp.sum(ab * ab, -1), 1e-12), 0.0, 1.0)
    near = jnp.min(jnp.linalg.norm(p - (a + t[..., None] * ab), axis=-1), axis=-1)  # [K]
    good = (near >= 0.95 * jnp.abs(shift) - 1e-4).at[0].set(True)
    return shifted[jax.lax.cummax(jnp.where(good, idx, 0))]


def perturb(rng: jax.Array, line3: jnp.ndarray, cum: jnp.ndarray, width: jnp.ndarray,
            rc: RouteConfig) -> jnp.ndarray:
    """[K, 3] the route of one episode: with chance rc.perturb_prob the centre-line line3
    [K, 3] (arc lengths cum [K]) made coarse, corner-cut and shifted (uniformly up to
    rc.lateral of the width to either side, or with chance rc.lateral_at_bound by that bound
    itself), else line3 itself."""
    k = jax.random.split(rng, 5)
    n = jax.random.randint(k[0], (), rc.coarse_points[0], rc.coarse_points[1] + 1)
    route = coarse(line3, cum, n)
    span = jax.random.uniform(k[1]) * rc.corner_cut_m
    route = cut_corners(route, span, jax.random.uniform(k[2]))
    u = jax.random.uniform(k[3], minval=-1.0, maxval=1.0)
    at_bound = jax.random.uniform(jax.random.fold_in(rng, 1)) < rc.lateral_at_bound
    u = jnp.where(at_bound, jnp.sign(u), u)
    offset = u * rc.lateral * width
    route = shift_sideways(route, offset)
    return jnp.where(jax.random.uniform(k[4]) < rc.perturb_prob, route, line3)


def draw(rng: jax.Array, tiles: TileTables, tile: jnp.ndarray,
         config: EnvConfig) -> dict[str, jnp.ndarray]:
    """This episode's route on ``tile``: {"route" [K, 3], "route_cum" [K]} when configured."""
    if not active(config):
        return {}
    route = perturb(jax.random.fold_in(rng, 5), tiles.line3[tile], tiles.line_cum[tile],
                    tiles.width[tile], config.route)
    return {"route": route, "route_cum": arc_lengths(route)}
