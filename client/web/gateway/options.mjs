// Command-line flags of the studio gateway (docs/studio.md, "Flags"). The listen rules are
// fieldspaced's: a non-loopback address needs a token (--auth-token-file), mutual TLS
// (--tls-client-ca) or an explicit --insecure.
import { readFileSync } from "node:fs";

export const USAGE = `usage: fieldspace-studio [--listen HOST:PORT] [--daemon HOST:PORT]
                         [--auth-token-file FILE] [--tls-cert PEM --tls-key PEM [--tls-client-ca PEM]]
                         [--daemon-ca PEM] [--insecure]

  --listen HOST:PORT      where the page, its API and the design WebSocket are served
                          (default 127.0.0.1:8750; port 0 = any free port). Non-loopback needs
                          --auth-token-file, --tls-client-ca or --insecure.
  --daemon HOST:PORT      the fieldspaced (or the scale-out router) to call (127.0.0.1:50051)
  --auth-token-file FILE  browsers must send this token; it is passed on to the daemon as
                          'authorization: Bearer <token>'
  --tls-cert PEM          serve HTTPS (and wss) with this certificate ...
  --tls-key PEM           ... and its private key
  --tls-client-ca PEM     mutual TLS: browsers need a certificate signed by this CA
  --daemon-ca PEM         call the daemon over TLS, trusting this CA
  --insecure              allow a non-loopback address without a token or client CA
`;

const VALUE_FLAGS = new Set(["listen", "daemon", "auth-token-file", "tls-cert", "tls-key",
  "tls-client-ca", "daemon-ca"]);
const SWITCHES = new Set(["insecure", "help"]);

/** Splits "host:port" ("[::1]:80" too); null when it is not one. */
export function splitHostPort(address) {
  const m = /^(?:\[([^\]]+)\]|([^:]*)):(\d{1,5})$/.exec(address);
  if (!m) return null;
  const port = Number(m[3]);
  if (port > 65535) return null;
  return { host: m[1] ?? m[2], port };
}

/** As fieldspaced's IsLoopbackListenAddress: localhost, ::1 and 127.0.0.0/8. */
export function isLoopback(host) {
  if (host === "localhost" || host === "::1") return true;
  const parts = host.split(".");
  return parts.length === 4 && parts.every((p) => /^\d+$/.test(p)) && Number(parts[0]) === 127;
}

/** The gateway's options from argv (without node and the script); throws Error with a message
 *  for the user on bad flags. */
export function parseOptions(argv) {
  const flags = {};
  for (let i = 0; i < argv.length; i++) {
    const arg = argv[i];
    if (!arg.startsWith("--")) throw new Error(`unexpected argument '${arg}'`);
    let name = arg.slice(2);
    let value;
    const eq = name.indexOf("=");
    if (eq >= 0) [name, value] = [name.slice(0, eq), name.slice(eq + 1)];
    if (SWITCHES.has(name)) {
      if (value !== undefined) throw new Error(`--${name} takes no value`);
      flags[name] = true;
    } else if (VALUE_FLAGS.has(name)) {
      if (value === undefined) {
        if (i + 1 >= argv.length) throw new Error(`--${name} needs a value`);
        value = argv[++i];
      }
      flags[name] = value;
    } else {
      throw new Error(`unknown flag --${name}`);
    }
  }
  const options = {
    help: Boolean(flags.help),
    listen: flags.listen ?? "127.0.0.1:8750",
    daemon: flags.daemon ?? "127.0.0.1:50051",
    token: "",
    tls: null,
    daemonCa: null,
    insecure: Boolean(flags.insecure),
  };
  if (options.help) return options;
  const listen = splitHostPort(options.listen);
  if (!listen) throw new Error(`--listen must be HOST:PORT, got '${options.listen}'`);
  options.host = listen.host;
  options.port = listen.port;
  if (!splitHostPort(options.daemon)) {
    throw new Error(`--daemon must be HOST:PORT, got '${options.daemon}'`);
  }
  if (flags["auth-token-file"] !== undefined) {
    options.token = readText(flags["auth-token-file"], "--auth-token-file").trim();
    if (!options.token) throw new Error(`--auth-token-file ${flags["auth-token-file"]} is empty`);
  }
  if ((flags["tls-cert"] === undefined) !== (flags["tls-key"] === undefined)) {
    throw new Error("--tls-cert and --tls-key go together");
  }
  if (flags["tls-client-ca"] !== undefined && flags["tls-cert"] === undefined) {
    throw new Error("--tls-client-ca needs --tls-cert and --tls-key");
  }
  if (flags["tls-cert"] !== undefined) {
    options.tls = {
      cert: readText(flags["tls-cert"], "--tls-cert"),
      key: readText(flags["tls-key"], "--tls-key"),
      clientCa: flags["tls-client-ca"] === undefined ? null
        : readText(flags["tls-client-ca"], "--tls-client-ca"),
    };
  }
  if (flags["daemon-ca"] !== undefined) options.daemonCa = readText(flags["daemon-ca"], "--daemon-ca");
  if (!isLoopback(options.host) && !options.token && !options.tls?.clientCa && !options.insecure) {
    throw new Error(`refusing to listen on non-loopback address ${options.listen} without ` +
      "--auth-token-file or --tls-client-ca (or say --insecure explicitly)");
  }
  return options;
}

function readText(path, flag) {
  try {
    return readFileSync(path, "utf8");
  } catch (e) {
    throw new Error(`cannot read ${flag} ${path}: ${e.code ?? e.message}`);
  }
}
