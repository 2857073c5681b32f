"""README truths: every shell or Python block in README.md is either run by a named test
(`<!-- tested-by: PATH -->` on the line before it, PATH a test that reads README.md) or says why it
is not run (`<!-- not run...: REASON -->`). The blocks tested by this file are run here as written
(with `build/bin/` standing for the build's binaries) and their output compared with the values the
README shows in its `# {...}` comment lines."""

import argparse
import json
import os
import re
import subprocess
import sys

RUNNABLE = ("sh", "bash", "python", "console", "shell")


def blocks(readme_text):
    """(language, tag line, body, line number) of every fenced block."""
    lines = readme_text.splitlines()
    out = []
    i = 0
    while i < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        lang, start = m.group(1), i
        j = i + 1
        while j < len(lines) and not lines[j].startswith("```"):
            j += 1
        tag = ""
        k = start - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        if k >= 0:
            tag = lines[k].strip()
        out.append((lang, tag, "\n".join(lines[start + 1:j]), start + 1))
        i = j + 1
    return out


def expected_values(body):
    """The key/value pairs (numbers, booleans) of the `# {...}` comment lines after a command."""
    comment = " ".join(l.strip()[1:] for l in body.splitlines() if l.strip().startswith("# "))
    return {k: json.loads(v) for k, v in re.findall(r'"(\w+)":(true|false|-?\d+(?:\.\d+)?)',
                                                      comment)}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--readme", required=True)
    parser.add_argument("--bin-dir", required=True)
    args = parser.parse_args()
    repo = os.path.dirname(os.path.abspath(args.readme))
    with open(args.readme) as f:
        text = f.read()

    failures = []
    mine = []
    for lang, tag, body, line in blocks(text):
        if lang not in RUNNABLE:
            continue
        m = re.fullmatch(r"<!-- tested-by: (\S+) -->", tag)
        if m:
            path = os.path.join(repo, m.group(1))
            if not os.path.isfile(path):
                failures.append("line %d: tested-by names a missing file %s" % (line, m.group(1)))
            elif "README" not in open(path).read():
                failures.append("line %d: %s does not read the README" % (line, m.group(1)))
            elif os.path.abspath(path) == os.path.abspath(__file__):
                mine.append((body, line))
            continue
        m = re.fullmatch(r"<!-- not run[^:]*: (.{10,}) -->", tag)
        if m:
            continue
        failures.append("line %d: a %s block neither tested-by a test nor marked 'not run: "
                        "reason'" % (line, lang or "plain"))

    mesh_dir = os.environ.get("FIELDSPACE_MESH_DIR", os.path.join(repo, "..", "shared", "meshes"))
    for body, line in mine:
        commands = [l for l in body.splitlines() if l.strip() and not l.strip().startswith("#")]
        expected = expected_values(body)
        for command in commands:
            missing = [w for w in command.split() if w.startswith("../shared/meshes/") and
                       not os.path.exists(os.path.join(mesh_dir, w[len("../shared/meshes/"):]))]
            if missing:
                print("README line %d: not run here, %s absent (set FIELDSPACE_MESH_DIR)" %
                      (line, missing[0]))
                continue
            command = command.replace("build/bin/", os.path.abspath(args.bin_dir) + "/")
            command = command.replace("../shared/meshes/", os.path.abspath(mesh_dir) + "/")
            p = subprocess.run(["bash", "-euo", "pipefail", "-c", command], cwd=repo,
                               capture_output=True, text=True, timeout=300)
            if p.returncode != 0:
                failures.append("line %d: `%s` failed (%d): %s" % (line, command, p.returncode,
                                                                    p.stderr[-1000:]))
                continue
            got = json.loads(p.stdout)
            for key, value in expected.items():
                if got.get(key) != value:
                    failures.append("line %d: the README shows %s = %r, the command prints %r" %
                                    (line, key, value, got.get(key)))
            print("README line %d: ran, %d values as shown" % (line, len(expected)))

    if failures:
        print("\n".join(failures))
        sys.exit(1)
    print("README blocks: all tagged; the runnable ones here match")


if __name__ == "__main__":
    main()
