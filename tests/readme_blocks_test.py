"""README truths: every shell or Python block in README.md and in docs/*.md is either run by a
named test (`<!-- tested-by: PATH -->` on the line before it, PATH a test that reads that file:
its text names README.md, or the page's file name for a docs page) or says why it is not run
(`<!-- not run...: REASON -->`). The blocks tested by this file (docs/development.md's
`fieldspace-bench mesh` block) are run here as written (with
`build/bin/` standing for the build's binaries) and their output compared with the values the page
shows in its `# {...}` comment lines."""

import glob

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
    pages = [os.path.abspath(args.readme)] + sorted(glob.glob(os.path.join(repo, "docs", "*.md")))

    failures = []
    mine = []
    for page in pages:
        name = os.path.relpath(page, repo)
        # What a test that runs this page's blocks must name: README for README.md, the file name
        # (cli.md, ...) for a docs page.
        read_mark = "README" if name == "README.md" else os.path.basename(page)
        with open(page) as f:
            text = f.read()
        for lang, tag, body, line in blocks(text):
            if lang not in RUNNABLE:
                continue
            where = "%s line %d" % (name, line)
            m = re.fullmatch(r"<!-- tested-by: (\S+) -->", tag)
            if m:
                path = os.path.join(repo, m.group(1))
                if not os.path.isfile(path):
                    failures.append("%s: tested-by names a missing file %s" % (where, m.group(1)))
                elif read_mark not in open(path).read():
                    failures.append("%s: %s does not read %s" % (where, m.group(1), name))
                elif os.path.abspath(path) == os.path.abspath(__file__):
                    mine.append((body, where))
                continue
            m = re.fullmatch(r"<!-- not run[^:]*: (.{10,}) -->", tag)
            if m:
                continue
            failures.append("%s: a %s block neither tested-by a test nor marked 'not run: "
                            "reason'" % (where, lang or "plain"))

    mesh_dir = os.environ.get("FIELDSPACE_MESH_DIR", os.path.join(repo, "..", "shared", "meshes"))
    for body, where in mine:
        commands = [l for l in body.splitlines() if l.strip() and not l.strip().startswith("#")]
        expected = expected_values(body)
        for command in commands:
            missing = [w for w in command.split() if w.startswith("../shared/meshes/") and
                       not os.path.exists(os.path.join(mesh_dir, w[len("../shared/meshes/"):]))]
            if missing:
                print("%s: not run here, %s absent (set FIELDSPACE_MESH_DIR)" %
                      (where, missing[0]))
                continue
            command = command.replace("build/bin/", os.path.abspath(args.bin_dir) + "/")
            command = command.replace("../shared/meshes/", os.path.abspath(mesh_dir) + "/")
            p = subprocess.run(["bash", "-euo", "pipefail", "-c", command], cwd=repo,
                               capture_output=True, text=True, timeout=300)
            if p.returncode != 0:
                failures.append("%s: `%s` failed (%d): %s" % (where, command, p.returncode,
                                                             p.stderr[-1000:]))
                continue
            got = json.loads(p.stdout)
            for key, value in expected.items():
                if got.get(key) != value:
                    failures.append("%s shows %s = %r, the command prints %r" %
                                    (where, key, value, got.get(key)))
            print("%s: ran, %d values as shown" % (where, len(expected)))

    if failures:
        print("\n".join(failures))
        sys.exit(1)
    print("README and docs blocks: all tagged; the runnable ones here match")


if __name__ == "__main__":
    main()
