#!/usr/bin/env python3
"""Per-point error of a result against a reference, for all points and apart for the
points under open sky and the enclosed ones (docs/results.md, "Sponza: open sky and
enclosed points").

    scripts/sky_split.py RESULT.csv REFERENCE.csv SKY.csv [THRESHOLD]

SKY.csv is what `surfcache points SCENE --sky-view POINTS.csv` writes for the same points:
a point is under open sky when at least THRESHOLD (default 0.9) of its cosine-weighted
directions meet no surface (roofs, outer walls), enclosed otherwise (courtyards,
galleries, rooms). The error is `surfcache compare`'s: per channel (E - R) / (R + eps),
eps = 1 % of the channel's mean over all lit reference points; per point the RMS over
the channels. Prints one JSON line per group: points, median_rel, p90_rel, rel_rms.
"""
import csv
import json
import math
import sys


def rows(path):
    return list(csv.DictReader(open(path)))


def quantile(sorted_values, q):
    h = (len(sorted_values) - 1) * q
    lo, hi = math.floor(h), math.ceil(h)
    return sorted_values[lo] + (h - lo) * (sorted_values[hi] - sorted_values[lo])


def main():
    result, reference, sky = rows(sys.argv[1]), rows(sys.argv[2]), rows(sys.argv[3])
    threshold = float(sys.argv[4]) if len(sys.argv) > 4 else 0.9
    if not (len(result) == len(reference) == len(sky)):
        sys.exit("error: the three files must have the same rows")
    lit = [i for i, r in enumerate(reference) if max(float(r[c]) for c in "rgb") > 0]
    eps = {c: 0.01 * sum(float(reference[i][c]) for i in lit) / len(lit) for c in "rgb"}
    errors = {}
    for i in lit:
        e, r = result[i], reference[i]
        d = [(float(e[c]) - float(r[c])) / (float(r[c]) + eps[c]) for c in "rgb"]
        if all(math.isfinite(x) for x in d):
            errors[i] = d
    groups = {
        "all": list(errors),
        "open_sky": [i for i in errors if float(sky[i]["sky"]) >= threshold],
        "enclosed": [i for i in errors if float(sky[i]["sky"]) < threshold],
    }
    for name, members in groups.items():
        if not members:
            continue
        per_point = sorted(math.sqrt(sum(x * x for x in errors[i]) / 3) for i in members)
        rms = math.sqrt(sum(x * x for i in members for x in errors[i]) / (3 * len(members)))
        print(json.dumps({
            "group": name,
            "points": len(members),
            "median_rel": round(quantile(per_point, 0.5), 6),
            "p90_rel": round(quantile(per_point, 0.9), 6),
            "rel_rms": round(rms, 6),
        }))


if __name__ == "__main__":
    main()
