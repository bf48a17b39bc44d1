// The served scene's bounding sphere from `/scene.glb`: every instance node's mesh bounds
// (the POSITION accessor's min/max, which psao serve writes) through the node's matrix.

/// Centre and radius of a sphere around every instance.
export interface Bounds {
  centre: [number, number, number];
  radius: number;
}

interface GltfDoc {
  nodes?: { mesh?: number; matrix?: number[] }[];
  meshes?: { primitives: { attributes: { POSITION?: number } }[] }[];
  accessors?: { min?: number[]; max?: number[] }[];
}

/// The bounds of the instances in binary glTF `glb`, or null when it holds none.
export function sceneBounds(glb: Uint8Array): Bounds | null {
  const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
  if (glb.length < 20 || view.getUint32(0, true) !== 0x46546c67) return null;
  const jsonLen = view.getUint32(12, true);
  if (view.getUint32(16, true) !== 0x4e4f534a || 20 + jsonLen > glb.length) return null;
  const doc: GltfDoc = JSON.parse(new TextDecoder().decode(glb.subarray(20, 20 + jsonLen)));
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (const node of doc.nodes ?? []) {
    if (node.mesh === undefined || !node.matrix) continue;
    const m = node.matrix;
    for (const prim of doc.meshes?.[node.mesh]?.primitives ?? []) {
      const acc = prim.attributes.POSITION !== undefined ? doc.accessors?.[prim.attributes.POSITION] : undefined;
      if (!acc?.min || !acc.max) continue;
      for (let corner = 0; corner < 8; corner++) {
        const p = [0, 1, 2].map((k) => ((corner >> k) & 1 ? acc.max![k] : acc.min![k]));
        for (let r = 0; r < 3; r++) {
          const v = m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r];
          lo[r] = Math.min(lo[r], v);
          hi[r] = Math.max(hi[r], v);
        }
      }
    }
  }
  if (!(lo[0] <= hi[0])) return null;
  const centre: [number, number, number] = [0, 1, 2].map((k) => (lo[k] + hi[k]) / 2) as [number, number, number];
  const radius = Math.max(Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2, 1e-3);
  return { centre, radius };
}
