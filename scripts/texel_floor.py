#!/usr/bin/env python3
"""The error a lightmap of texel size H has even when every texel is exact.

A lightmap answers a point from the four texel centres around it (bilinear). This script
places, around every query point, the four centres of a texel grid of spacing H with a
random orientation in the point's tangent plane and a random offset of the point inside
the cell, so that path-traced E at those centres, blended with the bilinear weights, is
what a perfect lightmap of that density would answer. Comparing that blend with the
reference (`surfcache compare`) gives the resolution floor of the density: the error no
number of samples per texel removes. Centres that fall inside a wall are kept as they
fall, as texels at contacts are; centres off every surface (past an edge, where
`surfcache reference` answers nan) drop out and the others' weights are renormalised, as
a lightmap's dilation fills texels past a chart's edge from inside.

    scripts/texel_floor.py centres POINTS.csv H SEED > CENTRES.csv
    surfcache reference SCENE --env ENV CENTRES.csv --samples N -o CENTRES_E.csv
    scripts/texel_floor.py blend POINTS.csv H SEED CENTRES_E.csv > BLEND.csv
    surfcache compare BLEND.csv REFERENCE.csv

(`docs/results.md`, Sponza: error against time.)
"""
import math
import random
import sys


def read_csv(path):
    with open(path) as f:
        header = f.readline().strip().split(",")
        return header, [list(map(float, line.split(","))) for line in f if line.strip()]


def layout(points, h, seed):
    """Per point: the four centres and their bilinear weights."""
    rng = random.Random(seed)
    out = []
    for x, y, z, nx, ny, nz in (p[:6] for p in points):
        # A tangent frame (Duff et al. 2017), turned by a random angle.
        s = math.copysign(1.0, nz)
        a = -1.0 / (s + nz)
        b = nx * ny * a
        t1 = (1.0 + s * nx * nx * a, s * b, -s * nx)
        t2 = (b, s + ny * ny * a, -ny)
        phi = rng.uniform(0.0, 2.0 * math.pi)
        c, si = math.cos(phi), math.sin(phi)
        u_axis = tuple(c * p + si * q for p, q in zip(t1, t2))
        v_axis = tuple(-si * p + c * q for p, q in zip(t1, t2))
        fu, fv = rng.random(), rng.random()
        corners = []
        for du, dv, w in (
            (0, 0, (1 - fu) * (1 - fv)),
            (1, 0, fu * (1 - fv)),
            (0, 1, (1 - fu) * fv),
            (1, 1, fu * fv),
        ):
            ou, ov = (du - fu) * h, (dv - fv) * h
            pos = tuple(
                o + ou * ua + ov * va for o, ua, va in zip((x, y, z), u_axis, v_axis)
            )
            corners.append((pos, (nx, ny, nz), w))
        out.append(corners)
    return out


def main():
    mode, points_path, h, seed = sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4])
    _, points = read_csv(points_path)
    cells = layout(points, h, seed)
    if mode == "centres":
        print("x,y,z,nx,ny,nz")
        for corners in cells:
            for pos, n, _ in corners:
                print(",".join(f"{v:.7g}" for v in (*pos, *n)))
    elif mode == "blend":
        _, centres = read_csv(sys.argv[5])
        if len(centres) != 4 * len(cells):
            sys.exit(f"{sys.argv[5]} has {len(centres)} rows, expected {4 * len(cells)}")
        print("x,y,z,r,g,b")
        for i, (p, corners) in enumerate(zip(points, cells)):
            rgb, total = [0.0, 0.0, 0.0], 0.0
            for k, (_, _, w) in enumerate(corners):
                e = centres[4 * i + k][3:6]
                if all(math.isfinite(v) for v in e):
                    rgb = [acc + w * v for acc, v in zip(rgb, e)]
                    total += w
            rgb = [v / total if total > 0.0 else math.nan for v in rgb]
            print(",".join(f"{v:.7g}" for v in (*p[:3], *rgb)))
    else:
        sys.exit(f"unknown mode '{mode}' (centres or blend)")


if __name__ == "__main__":
    main()
