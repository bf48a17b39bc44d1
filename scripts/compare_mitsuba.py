#!/usr/bin/env python3
"""Compares `psao reference --lighting gi` with Mitsuba 3, an independent path tracer.

The scene is a psao scene file whose assets are Wavefront OBJ files with diffuse MTL colours,
whose environment is a constant `sky`, and whose lights are suns and point lights
(`scenes/open_box.toml` is such a scene). The script renders the first key of the scene's
first camera path in Mitsuba with the same geometry, base colours, sky, lights and bounce
count, reads psao's HDR image of the same frame, and prints how far apart they are over the
pixels that see the scene away from geometric edges (psao's reference shades each pixel's
centre; Mitsuba's box filter averages over the pixel, so edge pixels differ by design).

    python3 -m venv venv && venv/bin/pip install mitsuba numpy
    psao reference --scene scenes/open_box.toml --lighting gi --bounces 1 --frame 0 \\
        --res 200x150 --spp 1024 --out ref
    venv/bin/python scripts/compare_mitsuba.py scenes/open_box.toml ref/gi_00000.hdr \\
        --bounces 1 --spp 1024

Mitsuba's `max_depth` counts path vertices from the camera: 2 is direct light only, so
psao's `--bounces B` (indirect bounces after the direct light) is `max_depth = B + 2`.
Surfaces are two-sided in Mitsuba as in psao. Exit status 0 with the figures on stdout.
"""

import argparse
import math
import pathlib
import sys
import tempfile
import tomllib

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")


def read_obj(path):
    """Vertices and triangles of an OBJ, grouped by `usemtl`, and its MTL diffuse colours."""
    vertices, groups, colours = [], {}, {}
    material = "default"
    for line in path.read_text().splitlines():
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        if words[0] == "mtllib":
            colours.update(read_mtl(path.parent / words[1]))
        elif words[0] == "v":
            vertices.append([float(w) for w in words[1:4]])
        elif words[0] == "usemtl":
            material = words[1]
        elif words[0] == "f":
            ids = [int(w.split("/")[0]) for w in words[1:]]
            ids = [i - 1 if i > 0 else len(vertices) + i for i in ids]
            tris = groups.setdefault(material, [])
            for k in range(1, len(ids) - 1):
                tris.append([ids[0], ids[k], ids[k + 1]])
    return np.array(vertices, dtype=np.float32), groups, colours


def read_mtl(path):
    """`Kd` per material name."""
    colours, name = {}, None
    for line in path.read_text().splitlines():
        words = line.split()
        if words and words[0] == "newmtl":
            name = words[1]
        elif words and words[0] == "Kd" and name is not None:
            colours[name] = [float(w) for w in words[1:4]]
    return colours


def ply_file(folder, name, vertices, triangles):
    """Writes the used vertices of `triangles` as a PLY mesh in `folder`; returns its path."""
    tris = np.array(triangles, dtype=np.uint32)
    used, remap = np.unique(tris, return_inverse=True)
    m = mi.Mesh(name, len(used), len(tris), has_vertex_normals=False)
    params = mi.traverse(m)
    params["vertex_positions"] = vertices[used].ravel()
    params["faces"] = remap.astype(np.uint32).ravel()
    params.update()
    path = folder / f"{name}.ply"
    m.write_ply(str(path))
    return path


def first_camera(scene_path, scene):
    """Position, target and vertical field of view of the first key of the first path."""
    path_file = scene_path.parent / scene["camera_paths"][0]
    doc = tomllib.loads(path_file.read_text())
    key = doc["key"][0]
    return key["position"], key["look_at"], doc.get("fov_y_deg", 60.0)


def emitters(scene):
    """Mitsuba emitters of the scene file's constant sky and its suns and point lights."""
    out = {"sky": {"type": "constant", "radiance": {"type": "rgb", "value": scene.get("sky", [0.6] * 3)}}}
    for i, light in enumerate(scene.get("light", [])):
        rgb = [c * light.get("power", 1.0) for c in light.get("color", [1.0, 1.0, 1.0])]
        if light["kind"] == "sun":
            d = np.array(light["direction"], dtype=float)
            d /= np.linalg.norm(d)
            out[f"light{i}"] = {"type": "directional", "direction": (-d).tolist(),
                                "irradiance": {"type": "rgb", "value": rgb}}
        elif light["kind"] == "point":
            out[f"light{i}"] = {"type": "point", "position": light["position"],
                                "intensity": {"type": "rgb", "value": rgb}}
        else:
            sys.exit(f"light {i}: kind {light['kind']!r} is not converted by this script")
    return out


def render(scene_path, width, height, bounces, spp, seed, folder):
    """Two Mitsuba radiance images (seeds `seed` and `seed + 1`) and a mask of the pixels
    away from geometric edges."""
    scene = tomllib.loads(scene_path.read_text())
    if "environment" in scene:
        sys.exit("an environment map is not converted by this script (use a constant sky)")
    doc = {"type": "scene"}
    for a, asset in enumerate(scene["asset"]):
        if any(k in asset for k in ("translation", "rotation_deg", "scale", "walk", "keys")):
            sys.exit(f"asset {a}: transforms are not converted by this script")
        vertices, groups, colours = read_obj(scene_path.parent / asset["file"])
        for name, tris in groups.items():
            rho = colours.get(name, [0.8, 0.8, 0.8])
            doc[f"{a}_{name}"] = {
                "type": "ply", "filename": str(ply_file(folder, f"{a}_{name}", vertices, tris)),
                "face_normals": True,
                "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": rho}}},
            }
    doc.update(emitters(scene))
    position, target, fov = first_camera(scene_path, scene)
    doc["camera"] = {
        "type": "perspective", "fov": fov, "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=position, target=target, up=[0, 1, 0]),
        "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}},
        "sampler": {"type": "independent", "sample_count": spp},
    }
    mi_scene = mi.load_dict(doc)
    path = mi.load_dict({"type": "path", "max_depth": bounces + 2})
    images = [np.array(mi.render(mi_scene, integrator=path, seed=s))[..., :3] for s in (seed, seed + 1)]
    depth = np.array(mi.render(mi_scene, integrator=mi.load_dict({"type": "aov", "aovs": "d:depth"}), spp=16))
    return images, interior(depth[..., 0])


def interior(depth):
    """Pixels that see a surface and whose 3×3 neighbours see it at nearly the same depth."""
    covered = depth > 0
    ok = covered.copy()
    h, w = depth.shape
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            shifted = np.zeros_like(depth)
            ys, yd = slice(max(dy, 0), h + min(dy, 0)), slice(max(-dy, 0), h + min(-dy, 0))
            xs, xd = slice(max(dx, 0), w + min(dx, 0)), slice(max(-dx, 0), w + min(-dx, 0))
            shifted[yd, xd] = depth[ys, xs]
            ok &= np.abs(shifted - depth) <= 0.02 * np.maximum(depth, 1e-6)
    return ok


def srgb8(linear):
    c = np.clip(linear, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.round(s * 255.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", type=pathlib.Path)
    ap.add_argument("psao_hdr", type=pathlib.Path, help="psao reference --lighting gi output (gi_NNNNN.hdr)")
    ap.add_argument("--bounces", type=int, default=1)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--save", type=pathlib.Path, help="also write Mitsuba's image here (.exr)")
    args = ap.parse_args()
    ours = np.array(mi.Bitmap(str(args.psao_hdr)))[..., :3].astype(np.float64)
    height, width = ours.shape[:2]
    with tempfile.TemporaryDirectory() as folder:
        (theirs, again), mask = render(args.scene, width, height, args.bounces, args.spp, args.seed, pathlib.Path(folder))
    if args.save:
        mi.Bitmap(theirs.astype(np.float32)).write(str(args.save))
    a, b, c = (x.astype(np.float64)[mask] for x in (ours, theirs, again))
    mean_a, mean_b = a.mean(axis=0), b.mean(axis=0)
    print(f"pixels compared: {mask.sum()} of {mask.size} (interior, covered)")
    print("mean radiance psao    R G B: " + " ".join(f"{v:.4f}" for v in mean_a))
    print("mean radiance Mitsuba R G B: " + " ".join(f"{v:.4f}" for v in mean_b))
    print("psao / Mitsuba        R G B: " + " ".join(f"{x / y:.4f}" for x, y in zip(mean_a, mean_b)))
    print(f"relative RMSE psao vs Mitsuba: {rel_rmse(a, b):.4f}; Mitsuba vs Mitsuba (another seed): {rel_rmse(c, b):.4f}")
    print(f"PSNR of the sRGB 8-bit images: psao vs Mitsuba {psnr8(a, b):.2f} dB; Mitsuba vs Mitsuba {psnr8(c, b):.2f} dB")


def rel_rmse(x, y):
    """Root mean square difference over the mean of `y`."""
    return math.sqrt(((x - y) ** 2).mean()) / y.mean()


def psnr8(x, y):
    """PSNR of the two images encoded as 8-bit sRGB."""
    mse = ((srgb8(x) - srgb8(y)) ** 2).mean()
    return float("inf") if mse == 0 else 10 * math.log10(255.0 ** 2 / mse)


if __name__ == "__main__":
    main()
