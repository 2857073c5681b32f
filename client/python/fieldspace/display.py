"""An X display for VTK on machines without one: a private Xvfb server, started on demand.

VTK's Debian build renders through GLX, which needs an X server even for off-screen images
(it aborts the process when it cannot connect). :func:`x_display` yields a usable ``DISPLAY``:
the caller's own one when ``DISPLAY`` is set, otherwise a private ``Xvfb`` (software OpenGL via
Mesa, no GPU) that this module starts once per process, protected by a fresh
MIT-MAGIC-COOKIE-1 in a private Xauthority file, listening on its Unix socket only, and stops at
exit (or on :func:`stop_private_display`).
"""

import atexit
import contextlib
import os
import re
import secrets
import select
import shutil
import struct
import subprocess
import tempfile
import threading
import time

_lock = threading.Lock()
_server = None


class DisplayError(RuntimeError):
    """No X display could be found or started."""


def _xauth_entry(cookie):
    """One Xauthority record for any host and display (FamilyWild) with ``cookie``."""
    def counted(data):
        return struct.pack(">H", len(data)) + data

    return (struct.pack(">H", 0xFFFF) + counted(b"") + counted(b"")
            + counted(b"MIT-MAGIC-COOKIE-1") + counted(cookie))


class _Xvfb:
    def __init__(self, width, height, timeout=20.0):
        binary = shutil.which("Xvfb")
        if binary is None:
            raise DisplayError("no DISPLAY is set and Xvfb is not installed "
                               "(Debian: apt-get install xvfb)")
        self.width, self.height = width, height
        self.dir = tempfile.mkdtemp(prefix="fieldspace-xvfb-")
        self.auth = os.path.join(self.dir, "Xauthority")
        with open(self.auth, "wb") as f:
            os.fchmod(f.fileno(), 0o600)
            f.write(_xauth_entry(secrets.token_bytes(16)))
        read_fd, write_fd = os.pipe()
        try:
            self.proc = subprocess.Popen(
                [binary, "-displayfd", str(write_fd), "-screen", "0",
                 "%dx%dx24" % (width, height), "-nolisten", "tcp", "-auth", self.auth,
                 "-nocursor", "-noreset"],
                pass_fds=(write_fd,), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE, start_new_session=True)
        finally:
            os.close(write_fd)
        number = b""
        deadline = time.monotonic() + timeout
        try:
            while not number.endswith(b"\n"):
                left = deadline - time.monotonic()
                ready, _, _ = select.select([read_fd], [], [], max(left, 0))
                if not ready:
                    raise DisplayError("Xvfb did not report a display within %gs" % timeout)
                chunk = os.read(read_fd, 16)
                if not chunk:
                    err = self.proc.stderr.read().decode(errors="replace")[-2000:]
                    raise DisplayError("Xvfb exited before it was ready: %s" % err)
                number += chunk
        except BaseException:
            self.stop()
            raise
        finally:
            os.close(read_fd)
        self.display = ":" + number.decode().strip()

    def alive(self):
        return self.proc.poll() is None

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stderr:
            self.proc.stderr.close()
        shutil.rmtree(self.dir, ignore_errors=True)


def stop_private_display():
    """Stops the private Xvfb if this process started one."""
    global _server
    with _lock:
        if _server is not None:
            _server.stop()
            _server = None


atexit.register(stop_private_display)


def _usable(display):
    """False for an unset DISPLAY and for a local one (":N") whose socket does not exist: VTK
    would abort the process on it. Remote displays are trusted."""
    if not display:
        return False
    match = re.fullmatch(r"(?:unix)?:(\d+)(?:\.\d+)?", display)
    if match is None:
        return True
    return os.path.exists("/tmp/.X11-unix/X%s" % match.group(1))


@contextlib.contextmanager
def x_display(width=1920, height=1080, use_existing=True):
    """Context manager: ``DISPLAY`` (and ``XAUTHORITY``) point at a working X server inside.

    With ``use_existing`` and ``DISPLAY`` set (to a local display whose socket exists, or a
    remote one), that display is used as is. Otherwise the private Xvfb (screen at least
    ``width`` x ``height``) is started or reused; the environment is restored on exit, the
    server keeps running for the next call until the process exits.
    """
    global _server
    if use_existing and _usable(os.environ.get("DISPLAY")):
        yield os.environ["DISPLAY"]
        return
    with _lock:
        if _server is not None and (not _server.alive() or _server.width < width
                                    or _server.height < height):
            _server.stop()
            _server = None
        if _server is None:
            _server = _Xvfb(max(width, 1920), max(height, 1080))
        server = _server
        saved = {k: os.environ.get(k) for k in ("DISPLAY", "XAUTHORITY")}
        os.environ["DISPLAY"] = server.display
        os.environ["XAUTHORITY"] = server.auth
        try:
            yield server.display
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
