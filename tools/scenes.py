"""Composite test scenes for --scope local: 2-4 regions, each a texture with a true pattern.

    scene = make_scene(seed, cells=32)          # a scene made for a 32 x 32 swarm
    scene.image      # uint8 (size x size) grey image, size 512 by default
    scene.region     # int (size x size): region index per pixel
    scene.patterns   # per region: 0 horizontal stripes, 1 vertical stripes, 2 mottled
    scene.truth      # int (size x size): true pattern per pixel (patterns[region])
    scene.info       # every drawn parameter (layout, per-region texture parameters, redraws)
    truth, region, dist = robot_truth(scene, rows, cols)   # per robot: true pattern, region,
                                                           # distance (cells) to a boundary

Every length (stripe period, blob size, blur) is drawn in *robot cells* of the grid the scene
is made for (`cells` x `cells` robots on a `size` x `size` image), so a scene made for 32x32
robots and one made for 64x64 are equally hard for their grids.

Layouts: straight (axis-aligned cuts: halves, strips, a T, quadrants), diagonal (Voronoi cells:
straight boundaries at any angle), curved (Voronoi cells in sinusoidally warped coordinates),
disc (1-3 discs in a background). Neighbouring regions get different patterns where possible;
with 3 or 4 regions all three patterns appear.
Textures: horizontal / vertical stripes (sine to square wave, period 1.5-6 cells log-uniform,
random phase, tilt up to 4 degrees, mean grey 100-160, half-amplitude 25-110) and mottled
(isotropic blobs: thresholded smoothed noise or scattered ellipses, blob radius 0.4-2 cells).
Then blur (up to 0.25 cell) and pixel noise (sd up to 12 grey levels).
Options: hard=True (half-amplitude from 18, looser visibility test), zoom=z (periods and blob
sizes times z). disc_scene(): one disc of one pattern inside another. orient_scene(): stripes
at any multiple of 15 degrees, for --orientation any.

A region's texture is accepted only if the paper's own descriptor can see it on the robot grid
(`visible`): on the texture alone, at the robots of that region two or more cells from its
boundary, the true pattern must be the plurality of the votes by a margin (0.1), and the
plurality of the 5x5-robot window around at least 80% of them. (A stripe of period near 2
cells in the wrong phase averages to flat grey in every robot's block: no rule on the robots
can know it is there.) Rejected textures are redrawn (68 rejections for 314 regions at 32
cells, 82 at 64, seeds 0-39 and 1000-1059); info counts them.

Command line: python scenes.py SEED [CELLS] writes scene_SEED.png, scene_SEED_regions.png
(region index * 60) and scene_SEED.json.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

H, V, M = 0, 1, 2
AMP_LO = 25.0
LAYOUTS = ("straight", "diagonal", "curved", "disc")


@dataclass
class Scene:
    image: np.ndarray
    region: np.ndarray
    patterns: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def truth(self) -> np.ndarray:
        return self.patterns[self.region]


# ---- region maps ---------------------------------------------------------------------------


def _grid(size):
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    return y / size, x / size  # 0..1


def _voronoi(rng, n, size, warp=0.0):
    y, x = _grid(size)
    if warp > 0:
        lam = rng.uniform(0.35, 0.8, 2)
        ph = rng.uniform(0, 2 * np.pi, 2)
        x, y = (
            x + warp * np.sin(2 * np.pi * y / lam[0] + ph[0]),
            y + warp * np.sin(2 * np.pi * x / lam[1] + ph[1]),
        )
    for _ in range(100):
        pts = rng.uniform(0.1, 0.9, (n, 2))
        d = np.linalg.norm(pts[:, None] - pts[None], axis=-1) + np.eye(n)
        if d.min() > 0.3:
            break
    dist = [(y - p[0]) ** 2 + (x - p[1]) ** 2 for p in pts]
    return np.argmin(np.stack(dist), axis=0), {"points": pts.round(3).tolist(), "warp": warp}


def _straight(rng, n, size):
    y, x = _grid(size)
    axis = rng.integers(2)
    a, b = (y, x) if axis == 0 else (x, y)
    if n == 2:
        c = rng.uniform(0.3, 0.7)
        return (a >= c).astype(int), {"cuts": [c], "axis": int(axis)}
    if n == 3:
        if rng.random() < 0.5:  # three strips
            c1 = rng.uniform(0.25, 0.42)
            c2 = rng.uniform(0.58, 0.75)
            return (a >= c1).astype(int) + (a >= c2).astype(int), {"strips": [c1, c2]}
        c1, c2 = rng.uniform(0.3, 0.7, 2)  # a T
        return np.where(a < c1, 0, np.where(b < c2, 1, 2)), {"tee": [c1, c2]}
    if rng.random() < 0.5:  # quadrants
        c1, c2 = rng.uniform(0.35, 0.65, 2)
        return (a >= c1).astype(int) * 2 + (b >= c2).astype(int), {"quadrants": [c1, c2]}
    cs = np.array([0.25, 0.5, 0.75]) + rng.uniform(-0.04, 0.04, 3)
    return sum((a >= c).astype(int) for c in cs), {"strips": cs.tolist()}


def _discs(rng, n, size):
    y, x = _grid(size)
    out = np.zeros((size, size), int)
    placed = []
    for k in range(1, n):
        for _ in range(500):
            r = rng.uniform(0.14, 0.26 if n == 2 else 0.2)
            c = rng.uniform(r + 0.03, 1 - r - 0.03, 2)
            if all(np.hypot(*(c - q)) > r + rq + 0.06 for q, rq in placed):
                break
        placed.append((c, r))
        out[(y - c[0]) ** 2 + (x - c[1]) ** 2 < r * r] = k
    return out, {"discs": [(q.round(3).tolist(), round(r, 3)) for q, r in placed]}


def region_map(rng, layout, n, size):
    if layout == "straight":
        return _straight(rng, n, size)
    if layout == "diagonal":
        return _voronoi(rng, n, size)
    if layout == "curved":
        return _voronoi(rng, n, size, warp=rng.uniform(0.04, 0.09))
    if layout == "disc":
        return _discs(rng, n, size)
    raise ValueError(layout)


def usable_region_map(rng, layout: str, n: int, size: int):
    """region_map drawn again (100 times at most) until all n regions are there, none under
    6% of the scene; the last one drawn otherwise."""
    for _ in range(100):
        region, info = region_map(rng, layout, n, size)
        areas = np.bincount(region.ravel(), minlength=n) / region.size
        if len(np.unique(region)) == n and areas.min() > 0.06:
            break
    return region, info


def _adjacent(region, n):
    adj = np.zeros((n, n), bool)
    for a, b in ((region[:-1], region[1:]), (region[:, :-1], region[:, 1:])):
        d = a != b
        adj[a[d], b[d]] = True
    return adj | adj.T


def assign_patterns(rng, region, n):
    """Neighbouring regions get different patterns where possible; 3+ regions use all three."""
    adj = _adjacent(region, n)
    for _ in range(200):
        if n == 2:
            pats = rng.choice(3, 2, replace=False)
        else:
            pats = np.concatenate([rng.permutation(3), rng.integers(0, 3, n - 3)])[:n]
            pats = rng.permutation(pats)
        if not any(adj[i, j] and pats[i] == pats[j] for i in range(n) for j in range(n) if i < j):
            return pats
    return pats  # some same-pattern neighbours (then with different texture parameters)


# ---- textures ------------------------------------------------------------------------------


def stripes(rng, size, cell, orient, amp_lo=AMP_LO, zoom=1.0):
    period = zoom * float(np.exp(rng.uniform(np.log(1.5), np.log(6.0))))
    tilt = rng.uniform(-4, 4)
    phase = rng.uniform(0, 2 * np.pi)
    sharp = rng.uniform(0.5, 6.0)  # 0.5 ~ sine, 6 ~ square
    mean = rng.uniform(100, 160)
    amp = rng.uniform(amp_lo, 110)
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    t = np.radians(tilt)
    across = (y * np.cos(t) + x * np.sin(t)) if orient == H else (x * np.cos(t) - y * np.sin(t))
    w = np.sin(2 * np.pi * across / (period * cell) + phase)
    w = np.tanh(sharp * w) / np.tanh(sharp)
    img = mean + amp * w
    return img, {
        "kind": "stripes",
        "period": round(period, 3),
        "tilt": round(tilt, 2),
        "phase": round(phase, 3),
        "sharp": round(sharp, 2),
        "mean": round(mean, 1),
        "amp": round(amp, 1),
    }


def mottled(rng, size, cell, amp_lo=AMP_LO, zoom=1.0):
    blob = zoom * float(np.exp(rng.uniform(np.log(0.4), np.log(2.0))))  # blob radius, cells
    mean = rng.uniform(100, 160)
    amp = rng.uniform(amp_lo, 110)
    kind = "noise" if rng.random() < 0.5 else "spots"
    if kind == "noise":
        sigma = blob * cell
        f = cv2.GaussianBlur(rng.normal(0, 1, (size, size)), (0, 0), sigma)
        f /= f.std() + 1e-12
        sharp = rng.uniform(0.7, 4.0)
        img = mean + amp * np.tanh(sharp * f) / np.tanh(sharp * 2)
        info = {"sharp": round(sharp, 2)}
    else:
        img = np.full((size, size), mean + amp)
        r = blob * cell
        density = rng.uniform(0.25, 0.5)  # fraction of area covered, roughly
        count = int(density * size * size / (np.pi * r * r))
        for _ in range(count):
            cx, cy = rng.uniform(-r, size + r, 2)
            ax = r * rng.uniform(0.7, 1.3)
            ay = r * rng.uniform(0.7, 1.3)
            cv2.ellipse(
                img,
                (int(cx), int(cy)),
                (max(1, int(ax)), max(1, int(ay))),
                float(rng.uniform(0, 180)),
                0,
                360,
                mean - amp,
                -1,
            )
        info = {"density": round(density, 2)}
    info.update(
        {
            "kind": "mottled-" + kind,
            "blob": round(blob, 3),
            "mean": round(mean, 1),
            "amp": round(amp, 1),
        }
    )
    return img, info


def finish(rng, img, cell):
    blur = rng.uniform(0.0, 0.25) * cell
    noise = rng.uniform(0.0, 12.0)
    if blur > 0.3:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    img = img + rng.normal(0, noise, img.shape)
    return np.clip(img, 0, 255), {"blur": round(blur / cell, 3), "noise": round(noise, 1)}


def texture(rng, pattern, size, cell, amp_lo=AMP_LO, zoom=1.0):
    """zoom scales the stripe period and blob size ranges (1: periods 1.5-6 cells)."""
    if pattern in (H, V):
        img, info = stripes(rng, size, cell, pattern, amp_lo, zoom)
    else:
        img, info = mottled(rng, size, cell, amp_lo, zoom)
    img, more = finish(rng, img, cell)
    info.update(more)
    return img, info


# ---- the visibility check ------------------------------------------------------------------


def paper_votes(gray, cells, thr=50.0):
    s = cv2.resize(gray.astype(np.float64), (cells, cells), interpolation=cv2.INTER_AREA)
    p = np.pad(s, 1, mode="reflect")  # interior robots see real neighbours; edges mirror
    px = p[1:-1, :-2] + p[1:-1, 2:] - 2 * s
    py = p[:-2, 1:-1] + p[2:, 1:-1] - 2 * s
    ax, ay = np.abs(px), np.abs(py)
    return np.where(ay - ax > thr, H, np.where(ax - ay > thr, V, M))


def visible(gray, pattern, cells, where=None, margin=0.1, window=5, share=0.8):
    """Can the paper's descriptor see `pattern` in this texture (alone) on a cells x cells grid,
    at the robots `where` (a cells x cells bool mask; default all)? The true pattern must be the
    plurality of their votes by `margin`, and the plurality of the votes in the window x window
    block around at least `share` of them."""
    votes = paper_votes(gray, cells)
    if where is None:
        where = np.ones(votes.shape, bool)
    onehot = (votes[..., None] == np.arange(3)).astype(np.float64)
    frac = onehot[where].mean(axis=0)
    others = np.delete(frac, pattern)
    if frac[pattern] < others.max() + margin:
        return False, frac
    box = cv2.blur(onehot, (window, window), borderType=cv2.BORDER_REFLECT)
    local = box.argmax(-1)[where] == pattern
    return bool(local.mean() >= share), frac


# ---- the scene -----------------------------------------------------------------------------


def make_scene(
    seed,
    cells=32,
    size=512,
    n_regions=None,
    layout=None,
    patterns=None,
    check=True,
    hard=False,
    zoom=1.0,
) -> Scene:
    """hard: weaker textures allowed (contrast from 18, visibility margin 0.05 and 60% of
    windows instead of 0.1 and 80%)."""
    margin, share, amp_lo = (0.05, 0.6, 18.0) if hard else (0.1, 0.8, AMP_LO)
    rng = np.random.default_rng(seed)
    n = int(n_regions or rng.integers(2, 5))
    layout = str(layout or rng.choice(LAYOUTS))
    cell = size / cells
    region, linfo = usable_region_map(rng, layout, n, size)
    pats = np.asarray(patterns if patterns is not None else assign_patterns(rng, region, n))
    image = np.zeros((size, size))
    tex_info, redraws = [], 0
    _, reg_c, dist_c = robot_truth(Scene(image, region, pats), cells, cells)
    for k in range(n):
        where = (reg_c == k) & (dist_c >= 2)
        if not where.any():
            where = reg_c == k
        for _ in range(200):
            img, info = texture(rng, int(pats[k]), size, cell, amp_lo, zoom)
            ok, frac = (
                visible(img, int(pats[k]), cells, where, margin=margin, share=share)
                if check
                else (True, None)
            )
            if ok:
                break
            redraws += 1
        if frac is not None:
            info["vote_shares"] = np.round(frac, 3).tolist()
        tex_info.append(info)
        image[region == k] = img[region == k]
    image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    info = {
        "seed": seed,
        "cells": cells,
        "hard": hard,
        "zoom": zoom,
        "size": size,
        "layout": layout,
        "regions": n,
        "layout_info": linfo,
        "textures": tex_info,
        "redraws": redraws,
    }
    return Scene(image, region, pats, info)


def disc_scene(seed, cells=32, radius=6.0, inner=H, outer=V, size=512, hard=False) -> Scene:
    """A disc of `inner` (radius in cells, centred, slightly jittered) inside `outer`."""
    rng = np.random.default_rng(seed)
    cell = size / cells
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    c = size / 2 + rng.uniform(-cell, cell, 2)
    region = ((y - c[0]) ** 2 + (x - c[1]) ** 2 < (radius * cell) ** 2).astype(int)
    pats = np.array([outer, inner])
    margin, share, amp_lo = (0.05, 0.6, 18.0) if hard else (0.1, 0.8, AMP_LO)
    _, reg_c, dist_c = robot_truth(Scene(np.zeros((size, size)), region, pats), cells, cells)
    image = np.zeros((size, size))
    tex_info = []
    for k in range(2):
        where = (reg_c == k) & (dist_c >= 2)
        if not where.any():
            where = reg_c == k
        for _ in range(200):
            img, info = texture(rng, int(pats[k]), size, cell, amp_lo)
            ok, _share = visible(img, int(pats[k]), cells, where, margin=margin, share=share)
            if ok:
                break
        tex_info.append(info)
        image[region == k] = img[region == k]
    image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    return Scene(
        image,
        region,
        pats,
        {"seed": seed, "layout": "disc", "radius": radius, "textures": tex_info},
    )


# ---- scoring helpers -----------------------------------------------------------------------


def robot_truth(scene: Scene, rows: int, cols: int):
    """Per robot: the true pattern at its block's centre, and the distance (in cells) from its
    centre to the nearest pixel of another region."""
    size = scene.region.shape[0]
    ch, cw = size / rows, size / cols
    cy = ((np.arange(rows) + 0.5) * ch).astype(int)
    cx = ((np.arange(cols) + 0.5) * cw).astype(int)
    region_c = scene.region[np.ix_(cy, cx)]
    dist = np.full((rows, cols), np.inf)
    for k in np.unique(scene.region):
        inside = (scene.region == k).astype(np.uint8)
        d = cv2.distanceTransform(inside, cv2.DIST_L2, 5)  # px to the nearest other pixel
        dk = d[np.ix_(cy, cx)] / ch
        dist = np.where(region_c == k, dk, dist)
    # the map's outer border is not a boundary
    return scene.patterns[region_c], region_c, dist


# ---- --orientation any: stripes at any multiple of 15 degrees -----------------------------


def angled_stripes(rng, size, cell, degrees, amp_lo=AMP_LO):
    """Stripes running at `degrees` (counter-clockwise from horizontal, y up, as --orientation
    any counts them), period 2-6 cells, sine to square, random phase / mean / contrast."""
    period = float(np.exp(rng.uniform(np.log(2.0), np.log(6.0))))
    phase = rng.uniform(0, 2 * np.pi)
    sharp = rng.uniform(0.5, 6.0)
    mean = rng.uniform(100, 160)
    amp = rng.uniform(max(amp_lo, 40), 110)
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    t = np.radians(degrees)
    across = -x * np.sin(t) - y * np.cos(t)
    w = np.sin(2 * np.pi * across / (period * cell) + phase)
    img = mean + amp * np.tanh(sharp * w) / np.tanh(sharp)
    return img, {
        "kind": "stripes",
        "degrees": degrees,
        "period": round(period, 3),
        "amp": round(amp, 1),
        "mean": round(mean, 1),
    }


def orient_scene(seed, cells=32, size=512, check_fn=None) -> Scene:
    """2-4 regions (any layout); each stripes at 15k degrees or mottled; neighbouring stripe
    regions differ by at least 30 degrees. patterns: 2 mottled, 3 + k stripes at 15k degrees
    (orientation.py's codes). check_fn(img, code, where) -> bool accepts a texture."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 5))
    layout = str(rng.choice(LAYOUTS))
    cell = size / cells
    region, _info = usable_region_map(rng, layout, n, size)
    adj = _adjacent(region, n)
    for _ in range(500):
        codes = np.where(rng.random(n) < 0.3, M, 3 + rng.integers(0, 12, n))
        ok = True
        for i in range(n):
            for j in range(i + 1, n):
                if adj[i, j]:
                    if codes[i] == M and codes[j] == M:
                        ok = False
                    elif codes[i] != M and codes[j] != M:
                        d = abs(int(codes[i]) - int(codes[j])) % 12
                        ok &= min(d, 12 - d) >= 2
        if ok:
            break
    _, reg_c, dist_c = robot_truth(Scene(np.zeros((size, size)), region, codes), cells, cells)
    image = np.zeros((size, size))
    infos = []
    for k in range(n):
        where = (reg_c == k) & (dist_c >= 2)
        if not where.any():
            where = reg_c == k
        for _ in range(100):
            if codes[k] == M:
                img, info = mottled(rng, size, cell)
            else:
                img, info = angled_stripes(rng, size, cell, 15 * (int(codes[k]) - 3))
            img, more = finish(rng, img, cell)
            info.update(more)
            if check_fn is None or check_fn(img, int(codes[k]), where):
                break
        infos.append(info)
        image[region == k] = img[region == k]
    image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    return Scene(
        image, region, codes, {"seed": seed, "layout": layout, "regions": n, "textures": infos}
    )


if __name__ == "__main__":
    import json
    import sys

    seed = int(sys.argv[1]) if len(sys.argv) > 1 else 0
    cells = int(sys.argv[2]) if len(sys.argv) > 2 else 32
    s = make_scene(seed, cells=cells)
    cv2.imwrite(f"scene_{seed}.png", s.image)
    cv2.imwrite(f"scene_{seed}_regions.png", (s.region * 60).astype(np.uint8))
    info = dict(s.info, patterns=s.patterns.tolist())
    with open(f"scene_{seed}.json", "w") as f:
        json.dump(info, f, indent=1, default=float)
    print(json.dumps(info, default=float)[:400])
