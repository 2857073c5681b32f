// Build step of the studio (docs/studio.md): generates the fieldspace.v1 messages and service
// descriptor from proto/fieldspace/v1/fieldspace.proto with protoc and protoc-gen-es (into gen/,
// used by the gateway and the page), then bundles the page with three.js into dist/ (esbuild).
// Nothing it writes is checked in.
import { execFileSync } from "node:child_process";
import { copyFileSync, mkdirSync, rmSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import * as esbuild from "esbuild";

const here = dirname(fileURLToPath(import.meta.url));
const protoRoot = join(here, "..", "..", "proto");
const protoc = process.env.PROTOC || "protoc";

rmSync(join(here, "gen"), { recursive: true, force: true });
mkdirSync(join(here, "gen"), { recursive: true });
execFileSync(protoc, [
  `--plugin=protoc-gen-es=${join(here, "node_modules", ".bin", "protoc-gen-es")}`,
  `--es_out=${join(here, "gen")}`,
  "--es_opt=target=js,import_extension=js",
  `-I${protoRoot}`,
  join(protoRoot, "fieldspace", "v1", "fieldspace.proto"),
], { stdio: "inherit" });

mkdirSync(join(here, "dist"), { recursive: true });
await esbuild.build({
  entryPoints: [join(here, "src", "main.js")],
  bundle: true,
  format: "esm",
  target: "es2022",
  minify: true,
  sourcemap: true,
  outfile: join(here, "dist", "studio.js"),
  logLevel: "warning",
});
for (const file of ["index.html", "studio.css"]) {
  copyFileSync(join(here, "src", file), join(here, "dist", file));
}
