#!/usr/bin/env python3
"""Writes a multi-primitive copy of a one-mesh skinned glTF (such as CesiumMan) for
`psao relight eval` (docs/RELIGHTING.md): the triangles cut into PIECES contiguous ranges,
the first half of the pieces as primitives of the original mesh and node, the rest as
primitives of a second mesh on a second node with its own copy of the skin; every primitive
shares the vertex attributes. The same construction as `split_copy` in
crates/psao/tests/relight.rs.

usage: split_gltf.py SRC.gltf OUT_DIR [PIECES]   (PIECES default 6)
"""
import copy
import json
import os
import shutil
import struct
import sys


def main():
    src, out = sys.argv[1], sys.argv[2]
    pieces = int(sys.argv[3]) if len(sys.argv) > 3 else 6
    folder = os.path.dirname(os.path.abspath(src))
    os.makedirs(out, exist_ok=True)
    for name in os.listdir(folder):
        shutil.copy(os.path.join(folder, name), os.path.join(out, name))
    g = json.load(open(src))
    prim = g["meshes"][0]["primitives"][0]
    acc = g["accessors"][prim["indices"]]
    view = g["bufferViews"][acc["bufferView"]]
    data = open(os.path.join(folder, g["buffers"][view["buffer"]]["uri"]), "rb").read()
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    fmt = {5123: "H", 5125: "I"}[acc["componentType"]]
    count = acc["count"]
    indices = struct.unpack_from("<%d%s" % (count, fmt), data, start)
    triangles = count // 3
    blob = b""
    primitives = []
    buffer = len(g["buffers"])
    for k in range(pieces):
        a, b = k * triangles // pieces, (k + 1) * triangles // pieces
        offset = len(blob)
        blob += struct.pack("<%dI" % (3 * (b - a)), *indices[3 * a:3 * b])
        g["bufferViews"].append({"buffer": buffer, "byteOffset": offset,
                                 "byteLength": len(blob) - offset, "target": 34963})
        g["accessors"].append({"bufferView": len(g["bufferViews"]) - 1,
                               "componentType": 5125, "count": 3 * (b - a), "type": "SCALAR"})
        p = copy.deepcopy(prim)
        p["indices"] = len(g["accessors"]) - 1
        primitives.append(p)
    open(os.path.join(out, "split_indices.bin"), "wb").write(blob)
    g["buffers"].append({"uri": "split_indices.bin", "byteLength": len(blob)})
    g["meshes"][0]["primitives"] = primitives[:pieces // 2]
    second = copy.deepcopy(g["meshes"][0])
    second["primitives"] = primitives[pieces // 2:]
    second["name"] = "second half"
    g["meshes"].append(second)
    g["skins"].append(copy.deepcopy(g["skins"][0]))
    skinned = next(i for i, n in enumerate(g["nodes"]) if "skin" in n)
    node = copy.deepcopy(g["nodes"][skinned])
    node.update({"mesh": len(g["meshes"]) - 1, "skin": len(g["skins"]) - 1,
                 "name": "second half"})
    g["nodes"].append(node)
    parents = [n for n in g["nodes"] if skinned in n.get("children", [])]
    if parents:
        parents[0]["children"].append(len(g["nodes"]) - 1)
    else:
        g["scenes"][0]["nodes"].append(len(g["nodes"]) - 1)
    stem = os.path.splitext(os.path.basename(src))[0]
    path = os.path.join(out, stem + "Split.gltf")
    json.dump(g, open(path, "w"))
    print(path)


if __name__ == "__main__":
    main()
