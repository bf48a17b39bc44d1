#!/usr/bin/env python3
"""Where one dumped corrected frame lost against its base.

Reads a frame dump of `psao corrective eval --dump-frames F` (`dump/*.json` of its `--out`)
and splits the change of squared error (8-bit sRGB, summed over the channels) from the base
frame to the corrected frame over the non-diffuse pixels by what reached each pixel:

- `own`: the pixel a drawn sample projects to (it shows that sample's radiance), by the
  sample's age (camera changes since it was traced: 0 = traced for this view);
- `level L`: pixels reached only by the footprints of samples whose finest level is L
  (approximate: object and distance only, no plane or normal test), by the youngest age;
- `none`: pixels no sample reaches (unchanged).

Then lists the pixels whose error grew most with the samples nearest to them.

Usage: scripts/corrective_dump.py out/x/dump/s1_generated_0_uniform_150_f53.json
"""

import json
import math
import sys
from collections import defaultdict


def srgb8(v):
    v = max(0.0, min(1.0, v))
    s = 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
    return int(s * 255.0 + 0.5)


def sq_err(a, b):
    return sum((srgb8(x) - srgb8(y)) ** 2 for x, y in zip(a, b))


def main(file):
    with open(file) as f:
        d = json.load(f)
    w, levels = d["width"], d["levels"]
    spacing = {l: math.sqrt(5) ** (levels - l) for l in range(1, levels + 1)}
    drawn = [
        s for s in d["samples"]
        if s["pixel"] is not None and s["id_there"] == s["object"]
        and abs(s["depth"][1] - s["depth"][0]) <= 0.02 * s["depth"][0]
        and s["normal_cos"] >= 0.9
    ]
    own = {}
    for s in drawn:
        key = tuple(s["pixel"])
        if key not in own or s["level"] >= own[key]["level"]:
            own[key] = s
    by_obj = defaultdict(list)
    for s in drawn:
        by_obj[s["object"]].append(s)
    total = defaultdict(float)
    count = defaultdict(int)
    rows = []
    base_err = corr_err = 0.0
    for p in d["pixels"]:
        eb = sq_err(p["base"], p["reference"])
        ec = sq_err(p["corrected"], p["reference"])
        base_err += eb
        corr_err += ec
        key = (p["x"], p["y"])
        if key in own:
            s = own[key]
            kind = f"own age {min(s['age'], 3)}{'+' if s['age'] >= 3 else ''}"
            near = [s]
        else:
            near = [
                s for s in by_obj[p["id"]]
                if math.hypot(s["pixel"][0] - p["x"], s["pixel"][1] - p["y"]) < spacing[s["level"]]
            ]
            if near:
                finest = max(s["level"] for s in near)
                near = [s for s in near if s["level"] == finest]
                age = min(s["age"] for s in near)
                kind = f"level {finest} age {min(age, 3)}{'+' if age >= 3 else ''}"
            else:
                kind = "none"
        total[kind] += ec - eb
        count[kind] += 1
        rows.append((ec - eb, p, near))
    print(f"{file}: {len(d['pixels'])} non-diffuse pixels, {len(d['samples'])} cached samples, "
          f"{len(drawn)} drawn; squared error base {base_err:.0f} -> corrected {corr_err:.0f}")
    print("| reached by | pixels | Δ squared error |")
    print("|---|---|---|")
    for kind in sorted(total):
        print(f"| {kind} | {count[kind]} | {total[kind]:+.0f} |")
    rows.sort(key=lambda r: -r[0])
    print("\nPixels whose error grew most:")
    for delta, p, near in rows[:12]:
        fmt = lambda c: "(" + ", ".join(f"{v:.3f}" for v in c) + ")"
        print(f"  ({p['x']}, {p['y']}) id {p['id']} Δ {delta:+.0f}: base {fmt(p['base'])} "
              f"corrected {fmt(p['corrected'])} reference {fmt(p['reference'])}")
        for s in near[:4]:
            print(f"      sample at {tuple(s['pixel'])} level {s['level']} age {s['age']} "
                  f"color {fmt(s['color'])}")


if __name__ == "__main__":
    main(sys.argv[1])
