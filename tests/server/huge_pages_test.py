#!/usr/bin/env python3
"""fieldspaced starts with glibc's malloc asking for transparent huge pages
(core/common/huge_pages.h; docs/design-notes.md, "Huge pages for malloc"), the real daemon:
- by default it re-executes itself at once (same pid, marked FIELDSPACE_HUGE_PAGES_REEXEC=1) with
  glibc.malloc.hugetlb=1 in GLIBC_TUNABLES, the user's other tunables kept, and serves;
- a user's own glibc.malloc.hugetlb stands, and FIELDSPACE_HUGE_PAGES=0 leaves malloc alone: no
  re-execution in either case.
Read from /proc/PID/environ of the running daemon. glibc's loader rewrites GLIBC_TUNABLES there
as it parses it (Debian's 2.36 drops glibc.malloc.hugetlb from the copy when other tunables
precede it), so the re-execution shows by the marker; the user's other tunables must still be
there. Where the kernel has THP off ("[never]"), or glibc is older than 2.35, the daemon must not
re-execute at all; that is checked instead.

Exit 0 on success, 1 on failure.
"""

import argparse
import os
import platform
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fs_testlib import Daemon, check, daemon_workdir, log  # noqa: E402

MARKER = "FIELDSPACE_HUGE_PAGES_REEXEC"


def environ(pid):
    with open("/proc/%d/environ" % pid, "rb") as f:
        entries = f.read().split(b"\0")
    env = {}
    for entry in entries:
        if b"=" in entry:
            key, value = entry.split(b"=", 1)
            env[key.decode()] = value.decode()
    return env


def thp_available():
    try:
        with open("/sys/kernel/mm/transparent_hugepage/enabled") as f:
            mode = f.read()
    except OSError:
        return False
    if "[always]" not in mode and "[madvise]" not in mode:
        return False
    name, version = platform.libc_ver()
    if name != "glibc":
        return False
    major, minor = (int(x) for x in version.split(".")[:2])
    return (major, minor) >= (2, 35)


def started_with(binary, work, daemons, env_changes):
    saved = {key: os.environ.get(key) for key in env_changes}
    for key, value in env_changes.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
    try:
        store = tempfile.mkdtemp(dir=work)
        daemon = Daemon(binary, store, log=os.path.join(work, "daemon.log"))
        daemons.append(daemon)
        daemon.start()
        env = environ(daemon.proc.pid)  # exec keeps the pid: this is the serving process
        check(daemon.stop() == 0, "daemon did not exit 0 on SIGTERM")
        return env
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--daemon", required=True)
    args = parser.parse_args()
    available = thp_available()
    log("transparent huge pages for malloc available here: %s" % available)
    daemons = []
    clean = {"GLIBC_TUNABLES": None, "FIELDSPACE_HUGE_PAGES": None, MARKER: None}
    with daemon_workdir("fs_huge_pages_", daemons) as (work, _, _):
        env = started_with(args.daemon, work, daemons, clean)
        check((env.get(MARKER) == "1") == available,
              "default start: marker %r with huge pages available: %s" % (env.get(MARKER), available))
        if available:
            check(env.get("GLIBC_TUNABLES") == "glibc.malloc.hugetlb=1",
                  "default start: GLIBC_TUNABLES %r" % env.get("GLIBC_TUNABLES"))
        else:
            check("GLIBC_TUNABLES" not in env, "GLIBC_TUNABLES set: %r" % env)

        env = started_with(args.daemon, work, daemons,
                           dict(clean, GLIBC_TUNABLES="glibc.malloc.arena_max=4"))
        check((env.get(MARKER) == "1") == available,
              "with another tunable: marker %r with huge pages available: %s"
              % (env.get(MARKER), available))
        check("glibc.malloc.arena_max=4" in env.get("GLIBC_TUNABLES", "").split(":"),
              "the user's tunable was lost: GLIBC_TUNABLES %r" % env.get("GLIBC_TUNABLES"))

        env = started_with(args.daemon, work, daemons,
                           dict(clean, GLIBC_TUNABLES="glibc.malloc.hugetlb=0"))
        check(env.get("GLIBC_TUNABLES") == "glibc.malloc.hugetlb=0" and MARKER not in env,
              "the user's own hugetlb=0 was not kept: %r" % env)

        env = started_with(args.daemon, work, daemons, dict(clean, FIELDSPACE_HUGE_PAGES="0"))
        check("GLIBC_TUNABLES" not in env and MARKER not in env,
              "FIELDSPACE_HUGE_PAGES=0 still re-executed: %r" % env)
    log("ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
