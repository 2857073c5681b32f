// Files of the designed field for other tools, written in the page from the whole lifted field
// (ambient values of every face, from the daemon's Lift): Directional's raw field and a VTK XML
// unstructured grid, in the layouts of client/python/fieldspace/export.py (docs/exports.md,
// Formats), so that the same readers take both.
import { nfieldDirections, principal } from "./glyphs.js";

const LINES_PER_PART = 8192;  // text is built as Blob parts of this many lines (bounded strings)

// Per face, the directions a raw field lists: the vector (N = 1), the n directions of an n-field,
// or a tensor's principal cross as a unit 4-field (max, min, -max, -min).
function rawDirections(field, frames, values, f) {
  const n = [0, 1, 2].map((k) => frames.normals[3 * f + k]);
  if (field.kind === "tensor") {
    const { e1, e2 } = principal(Array.from(values.subarray(6 * f, 6 * f + 6)), n);
    return [e1, e2, e1.map((x) => -x), e2.map((x) => -x)];
  }
  const u = Array.from(values.subarray(3 * f, 3 * f + 3));
  if (field.kind === "vector") return [u];
  const m = Math.hypot(...u);
  return nfieldDirections(m > 0 ? u.map((x) => x / m) : u, field.n, n)
    .map((d) => d.map((x) => x * m));
}

/** Directional's .rawfield: "N #F", then per face the N directions x0 y0 z0 x1 y1 z1 ... */
export function rawfieldBlob(field, frames, values) {
  const F = frames.areas.length;
  const N = field.kind === "tensor" ? 4 : field.n;
  const parts = [`${N} ${F}\n`];
  let lines = [];
  for (let f = 0; f < F; f++) {
    lines.push(rawDirections(field, frames, values, f).flat().map(String).join(" "));
    if (lines.length === LINES_PER_PART) {
      parts.push(`${lines.join("\n")}\n`);
      lines = [];
    }
  }
  if (lines.length) parts.push(`${lines.join("\n")}\n`);
  return new Blob(parts, { type: "text/plain" });
}

// The cell arrays of export.py's field_arrays: [name, components, (f) -> values].
function cellArrays(field, frames, values) {
  const normal = (f) => [0, 1, 2].map((k) => frames.normals[3 * f + k]);
  if (field.kind === "vector") {
    const v = (f) => Array.from(values.subarray(3 * f, 3 * f + 3));
    return [["field", 3, v], ["field_magnitude", 1, (f) => [Math.hypot(...v(f))]]];
  }
  if (field.kind === "nfield") {
    const arrays = [];
    for (let k = 0; k < field.n; k++) {
      arrays.push([`field_dir${k}`, 3, (f) => rawDirections(field, frames, values, f)[k]]);
    }
    arrays.push(["field_magnitude", 1,
      (f) => [Math.hypot(...values.subarray(3 * f, 3 * f + 3))]]);
    return arrays;
  }
  const six = (f) => Array.from(values.subarray(6 * f, 6 * f + 6));
  const p = (f) => principal(six(f), normal(f));
  return [
    ["field", 9, (f) => {
      const [xx, yy, zz, xy, yz, zx] = six(f);
      return [xx, xy, zx, xy, yy, yz, zx, yz, zz];
    }],
    ["field_principal_values", 2, (f) => [p(f).l1, p(f).l2]],
    ["field_principal_max", 3, (f) => p(f).e1],
    ["field_principal_min", 3, (f) => p(f).e2],
    ["field_norm", 1, (f) => {
      const [xx, yy, zz, xy, yz, zx] = six(f);
      return [Math.sqrt(xx * xx + yy * yy + zz * zz + 2 * (xy * xy + yz * yz + zx * zx))];
    }],
  ];
}

/** A VTK XML UnstructuredGrid of the mesh's triangles with the field as cell arrays (ASCII
 *  float64, as export.py's write_vtu with binary=False). */
export function vtuBlob(field, positions, faces, frames, values) {
  const V = positions.length / 3, F = faces.length / 3;
  const arrays = cellArrays(field, frames, values);
  const active = (k) => arrays.find(([, c]) => c === k)?.[0];
  const attrs = [["Scalars", 1], ["Vectors", 3], ["Tensors", 9]]
    .filter(([, k]) => active(k)).map(([a, k]) => ` ${a}="${active(k)}"`).join("");
  const parts = [
    '<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="1.0" ' +
    'byte_order="LittleEndian" header_type="UInt64">\n<UnstructuredGrid>\n' +
    `<Piece NumberOfPoints="${V}" NumberOfCells="${F}">\n<Points>\n` +
    '<DataArray type="Float64" NumberOfComponents="3" format="ascii">\n'];
  const rows = (count, row) => {
    let lines = [];
    for (let i = 0; i < count; i++) {
      lines.push(row(i));
      if (lines.length === LINES_PER_PART) {
        parts.push(`${lines.join("\n")}\n`);
        lines = [];
      }
    }
    if (lines.length) parts.push(`${lines.join("\n")}\n`);
  };
  rows(V, (i) => `${positions[3 * i]} ${positions[3 * i + 1]} ${positions[3 * i + 2]}`);
  parts.push('</DataArray>\n</Points>\n<Cells>\n' +
    '<DataArray type="Int64" Name="connectivity" format="ascii">\n');
  rows(F, (f) => `${faces[3 * f]} ${faces[3 * f + 1]} ${faces[3 * f + 2]}`);
  parts.push('</DataArray>\n<DataArray type="Int64" Name="offsets" format="ascii">\n');
  rows(F, (f) => String(3 * f + 3));
  parts.push('</DataArray>\n<DataArray type="UInt8" Name="types" format="ascii">\n');
  rows(F, () => "5");
  parts.push(`</DataArray>\n</Cells>\n<CellData${attrs}>\n`);
  for (const [name, components, at] of arrays) {
    parts.push(`<DataArray type="Float64" Name="${name}" NumberOfComponents="${components}" ` +
      'format="ascii">\n');
    rows(F, (f) => at(f).map(String).join(" "));
    parts.push("</DataArray>\n");
  }
  parts.push("</CellData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
  return new Blob(parts, { type: "application/xml" });
}
