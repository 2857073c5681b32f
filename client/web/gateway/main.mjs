#!/usr/bin/env node
// fieldspace-studio: the studio's gateway (docs/studio.md). Prints "studio: URL" once serving.
import { startGateway } from "./gateway.mjs";
import { parseOptions, USAGE } from "./options.mjs";

let options;
try {
  options = parseOptions(process.argv.slice(2));
} catch (e) {
  process.stderr.write(`${USAGE}\nfieldspace-studio: ${e.message}\n`);
  process.exit(2);
}
if (options.help) {
  process.stdout.write(USAGE);
  process.exit(0);
}
let gateway;
try {
  gateway = await startGateway(options);
} catch (e) {
  process.stderr.write(`fieldspace-studio: cannot listen on ${options.listen}: ${e.message}\n`);
  process.exit(1);
}
process.stdout.write(`studio: ${gateway.url}\n`);
for (const signal of ["SIGINT", "SIGTERM"]) {
  process.on(signal, async () => {
    await gateway.close();
    process.exit(0);
  });
}
