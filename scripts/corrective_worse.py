#!/usr/bin/env python3
"""Where corrected frames worse than their base lost, from a `psao corrective eval` run.

Reads the `seeds.json` of `psao corrective eval --seeds ...` (or the `report.json` of a single
run) and prints, per ordering and budget, the corrected frames worse than the base frame
(lower PSNR / higher FLIP) and how their squared error changed against the base by kind of
non-diffuse pixel (`worse_pixels` of `per_frame`: edges of objects, highlights, interior),
summed over those frames.

Usage: scripts/corrective_worse.py out/corrective_gi/seeds.json
"""

import json
import sys
from collections import defaultdict


def paths_of(report):
    if "runs" in report:
        return [(run["seed"], p) for run in report["runs"] for p in run["paths"]]
    return [(None, p) for p in report["paths"]]


def budget_name(budget):
    (kind, value), = budget.items()
    return f"{value}" if kind == "samples" else f"{value} ms"


def main(file):
    with open(file) as f:
        report = json.load(f)
    frames = defaultdict(int)
    worse = defaultdict(lambda: defaultdict(float))
    examples = defaultdict(list)
    for seed, path in paths_of(report):
        base = {r["frame"]: r for r in path["per_frame"] if r["order"] == "base"}
        for r in path["per_frame"]:
            if r["order"] == "base":
                continue
            key = (r["order"], budget_name(r["budget"]))
            frames[key] += 1
            change = r.get("worse_pixels")
            if change is None:
                continue
            b = base[r["frame"]]
            w = worse[key]
            w["psnr"] += r["psnr"] < b["psnr"]
            w["flip"] += r["flip"] > b["flip"]
            for kind in ("edge", "highlight", "interior"):
                w[kind] += change[kind]
                w[kind + "_worse"] += change[kind + "_worse"]
            examples[key].append(
                f"seed {seed} {path['path']} frame {r['frame']}: "
                f"{r['psnr'] - b['psnr']:+.2f} dB, FLIP {r['flip'] - b['flip']:+.4f}"
            )
    print("| order | budget | frames | worse PSNR | worse FLIP | Δ squared error: edges | highlights | interior | pixels worse: edges / highlights / interior |")
    print("|---|---|---|---|---|---|---|---|---|")
    for key in sorted(frames):
        w = worse[key]
        print(
            f"| {key[0]} | {key[1]} | {frames[key]} | {int(w['psnr'])} | {int(w['flip'])} | "
            f"{w['edge']:+.0f} | {w['highlight']:+.0f} | {w['interior']:+.0f} | "
            f"{int(w['edge_worse'])} / {int(w['highlight_worse'])} / {int(w['interior_worse'])} |"
        )
    for key in sorted(examples):
        for line in examples[key][:4]:
            print(f"{key[0]} {key[1]}: {line}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
