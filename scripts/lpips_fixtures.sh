#!/usr/bin/env bash
# Renders the LPIPS agreement fixtures: 20 pairs of AO images of the built-in scene at 96x54
# (reference at 256 spp against a 4-spp reference and against `psao run` at 256 points/m²),
# frames 0, 60, 120, 180, 240 of both built-in paths. Then compute the expected distances
# with the Python package: python3 scripts/lpips_check.py crates/psao-eval/tests/fixtures/lpips
#
# usage: scripts/lpips_fixtures.sh [PSAO_BINARY]   (default: target/release/psao)
set -euo pipefail
psao=${1:-target/release/psao}
out=crates/psao-eval/tests/fixtures/lpips
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"
res=96x54
for p in a b; do
  path=paths/default_$p.toml
  "$psao" --log warn run --path "$path" --res $res --frames 0..241 --every 60 \
    --points 256 --ray-budget 200000 --out "$tmp/run_$p"
  for f in 0 60 120 180 240; do
    n=$(printf %05d $f)
    "$psao" --log warn reference --path "$path" --frame $f --spp 256 --res $res --out "$tmp/ref_$p"
    "$psao" --log warn reference --path "$path" --frame $f --spp 4 --seed 7 --res $res --out "$tmp/noisy_$p"
    cp "$tmp/ref_$p/ao_$n.png" "$out/${p}_${n}_ref.png"
    cp "$tmp/noisy_$p/ao_$n.png" "$out/${p}_${n}_spp4.png"
    cp "$tmp/run_$p/ao_$n.png" "$out/${p}_${n}_psao256.png"
  done
done
ls "$out"
