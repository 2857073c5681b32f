// Geometry of the field glyphs, without three.js: which faces carry a glyph (an even sample) and
// the line segments drawn for a field's ambient values on them (docs/studio.md, "Drawing").

/** Per-face centroids, unit normals and areas of a mesh (positions: 3 per vertex, faces: 3 per
 *  face). */
export function faceFrames(positions, faces) {
  const F = faces.length / 3;
  const centroids = new Float64Array(3 * F);
  const normals = new Float64Array(3 * F);
  const areas = new Float64Array(F);
  for (let f = 0; f < F; f++) {
    const a = 3 * faces[3 * f], b = 3 * faces[3 * f + 1], c = 3 * faces[3 * f + 2];
    const ux = positions[b] - positions[a], uy = positions[b + 1] - positions[a + 1];
    const uz = positions[b + 2] - positions[a + 2];
    const vx = positions[c] - positions[a], vy = positions[c + 1] - positions[a + 1];
    const vz = positions[c + 2] - positions[a + 2];
    const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const len = Math.hypot(nx, ny, nz);
    areas[f] = len / 2;
    normals[3 * f] = len > 0 ? nx / len : 0;
    normals[3 * f + 1] = len > 0 ? ny / len : 0;
    normals[3 * f + 2] = len > 0 ? nz / len : 0;
    for (let k = 0; k < 3; k++) {
      centroids[3 * f + k] = (positions[a + k] + positions[b + k] + positions[c + k]) / 3;
    }
  }
  return { centroids, normals, areas };
}

/**
 * An even sample of about `target` faces: the surface is cut into cubes of side
 * h = sqrt(total area / target) and the face whose centroid is nearest each occupied cube's
 * centre is kept. Returns { faces: Int32Array (ascending), spacing: h }.
 */
export function sampleFaces(frames, target) {
  const { areas } = frames;
  let total = 0;
  for (let f = 0; f < areas.length; f++) total += areas[f];
  return sampleFacesSpaced(frames, Math.sqrt(total / Math.max(1, target)));
}

/**
 * An even sample of spacing h among the faces that `keep(face)` accepts (all without it): one
 * face per occupied cube of side h, the one whose centroid is nearest the cube's centre.
 * Returns { faces: Int32Array (ascending), spacing: h }.
 */
export function sampleFacesSpaced(frames, h, keep = null) {
  const { centroids, areas } = frames;
  const F = areas.length;
  // Cubes are numbered (i * ny + j) * nz + k from the centroids' bounding box: exact integers
  // (well below 2^53 for any h the page uses), so the map has number keys (a 1.4M-face mesh:
  // 0.14 s instead of 0.7 s with string keys, node, one core).
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let f = 0; f < F; f++) {
    for (let c = 0; c < 3; c++) {
      lo[c] = Math.min(lo[c], centroids[3 * f + c]);
      hi[c] = Math.max(hi[c], centroids[3 * f + c]);
    }
  }
  const ny = Math.floor((hi[1] - lo[1]) / h) + 1, nz = Math.floor((hi[2] - lo[2]) / h) + 1;
  const best = new Map();  // cube -> slot in face / distance
  const face = [];
  const distance = [];
  for (let f = 0; f < F; f++) {
    if (keep !== null && !keep(f)) continue;
    const x = (centroids[3 * f] - lo[0]) / h, y = (centroids[3 * f + 1] - lo[1]) / h;
    const z = (centroids[3 * f + 2] - lo[2]) / h;
    const i = Math.floor(x), j = Math.floor(y), k = Math.floor(z);
    const d = (x - i - 0.5) ** 2 + (y - j - 0.5) ** 2 + (z - k - 0.5) ** 2;
    const key = (i * ny + j) * nz + k;
    const slot = best.get(key);
    if (slot === undefined) {
      best.set(key, face.length);
      face.push(f);
      distance.push(d);
    } else if (d < distance[slot]) {
      face[slot] = f;
      distance[slot] = d;
    }
  }
  return { faces: Int32Array.from(face).sort(), spacing: h };
}

// A perceptually ordered colour ramp (viridis, 5 stops) for t in [0, 1].
const RAMP = [[0.267, 0.005, 0.329], [0.230, 0.322, 0.546], [0.128, 0.567, 0.551],
  [0.369, 0.789, 0.383], [0.993, 0.906, 0.144]];
export function rampColor(t) {
  const x = Math.min(1, Math.max(0, t)) * (RAMP.length - 1);
  const i = Math.min(RAMP.length - 2, Math.floor(x));
  const s = x - i;
  return RAMP[i].map((c, k) => c + s * (RAMP[i + 1][k] - c));
}

function cross(a, b) {
  return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
}

function normalize(v) {
  const l = Math.hypot(v[0], v[1], v[2]);
  return l > 0 ? [v[0] / l, v[1] / l, v[2] / l] : [0, 0, 0];
}

// Any unit vector orthogonal to the unit normal n.
function tangent(n) {
  const a = Math.abs(n[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
  return normalize(cross(n, a));
}

/** The n directions of an n-field whose direction 0 is u, on a face with unit normal n: direction
 *  k is u turned by 2 pi k / n counter-clockwise about n (docs/exports.md, Arrays). */
export function nfieldDirections(u, count, n) {
  const w = cross(n, u);
  const out = [];
  for (let k = 0; k < count; k++) {
    const a = (2 * Math.PI * k) / count;
    out.push([0, 1, 2].map((j) => Math.cos(a) * u[j] + Math.sin(a) * w[j]));
  }
  return out;
}

/** The principal values l1 >= l2 and unit directions e1, e2 = n x e1 of a tensor given as ambient
 *  [xx yy zz xy yz zx] on a face with unit normal n (its restriction to the tangent plane). */
export function principal(v, n) {
  const [xx, yy, zz, xy, yz, zx] = v;
  const S = [[xx, xy, zx], [xy, yy, yz], [zx, yz, zz]];
  const t1 = tangent(n), t2 = cross(n, t1);
  const q = (a, b) => a[0] * (S[0][0] * b[0] + S[0][1] * b[1] + S[0][2] * b[2]) +
    a[1] * (S[1][0] * b[0] + S[1][1] * b[1] + S[1][2] * b[2]) +
    a[2] * (S[2][0] * b[0] + S[2][1] * b[1] + S[2][2] * b[2]);
  const a11 = q(t1, t1), a12 = q(t1, t2), a22 = q(t2, t2);
  const mean = (a11 + a22) / 2, r = Math.hypot((a11 - a22) / 2, a12);
  const theta = 0.5 * Math.atan2(2 * a12, a11 - a22);
  const e1 = [0, 1, 2].map((k) => Math.cos(theta) * t1[k] + Math.sin(theta) * t2[k]);
  return { l1: mean + r, l2: mean - r, e1, e2: cross(n, e1) };
}

/**
 * The glyphs of one field on the sampled faces, as line segments: { positions, colors }
 * (Float32Array, 2 points of 3 values per segment) and the largest magnitude.
 *   field: { kind: "vector" | "nfield" | "tensor", n }
 *   values: the watched faces' ambient values (3 per face; 6 per face [xx yy zz xy yz zx] for
 *   tensors), in the order of `faces`.
 * Vectors are arrows, n-fields n-crosses (n spokes), tensors their principal crosses (both
 * eigen-directions in the tangent plane). Lengths grow with the magnitude from 0.3 to 0.9 spacing
 * (so that weak regions still show their directions) and colours follow it on the ramp.
 */
export function fieldGlyphs(field, frames, faces, values, spacing) {
  const per = field.kind === "tensor" ? 6 : 3;
  const count = faces.length;
  const mags = new Float64Array(count);
  const dirs = [];  // per face: list of [direction (unit), half length factor]
  for (let i = 0; i < count; i++) {
    const f = faces[i];
    const n = [frames.normals[3 * f], frames.normals[3 * f + 1], frames.normals[3 * f + 2]];
    const v = Array.from(values.subarray(per * i, per * i + per));
    if (field.kind === "tensor") {
      const { l1, l2, e1, e2 } = principal(v, n);
      mags[i] = Math.hypot(l1, l2);
      dirs.push([[e1, Math.abs(l1)], [[-e1[0], -e1[1], -e1[2]], Math.abs(l1)],
        [e2, Math.abs(l2)], [[-e2[0], -e2[1], -e2[2]], Math.abs(l2)]]);
    } else {
      mags[i] = Math.hypot(v[0], v[1], v[2]);
      const u = normalize(v);
      if (field.kind === "vector") {
        dirs.push([[u, mags[i]]]);
      } else {
        dirs.push(nfieldDirections(u, field.n, n).map((d) => [d, mags[i]]));
      }
    }
  }
  let maxMag = 0;
  for (let i = 0; i < count; i++) maxMag = Math.max(maxMag, mags[i]);
  // Half length of a glyph of magnitude m (tensor axes: of eigenvalue magnitude m).
  const halfLength = (m) => (maxMag > 0 && m > 0 ? 0.45 * spacing * (0.3 + 0.7 * m / maxMag) : 0);
  const lift = 0.02 * spacing;  // above the surface, so the mesh does not hide the glyph
  const positions = [];
  const colors = [];
  const segment = (a, b, color) => {
    positions.push(a[0], a[1], a[2], b[0], b[1], b[2]);
    colors.push(...color, ...color);
  };
  for (let i = 0; i < count; i++) {
    const f = faces[i];
    const n = [frames.normals[3 * f], frames.normals[3 * f + 1], frames.normals[3 * f + 2]];
    const c = [0, 1, 2].map((k) => frames.centroids[3 * f + k] + lift * n[k]);
    const color = rampColor(maxMag > 0 ? mags[i] / maxMag : 0);
    if (field.kind === "vector") {
      const [u, m] = dirs[i][0];
      const half = halfLength(m);
      const tail = [0, 1, 2].map((k) => c[k] - half * u[k]);
      const tip = [0, 1, 2].map((k) => c[k] + half * u[k]);
      segment(tail, tip, color);
      const side = cross(n, u);
      for (const s of [-1, 1]) {
        segment(tip, [0, 1, 2].map((k) => tip[k] - 0.6 * half * u[k] + s * 0.3 * half * side[k]),
          color);
      }
    } else {
      for (const [u, m] of dirs[i]) {
        segment(c, [0, 1, 2].map((k) => c[k] + halfLength(m) * u[k]), color);
      }
    }
  }
  return { positions: new Float32Array(positions), colors: new Float32Array(colors), maxMag };
}

/** The ambient constraint value for a drag direction d (unit, tangent): the vector itself for
 *  vector and n-fields, the rank-one tensor d d^T [xx yy zz xy yz zx] for tensors. */
export function constraintValue(field, d) {
  if (field.kind !== "tensor") return [d[0], d[1], d[2]];
  return [d[0] * d[0], d[1] * d[1], d[2] * d[2], d[0] * d[1], d[1] * d[2], d[2] * d[0]];
}
