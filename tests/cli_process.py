"""`robocal` command lines run as processes of their own, forked from one that has imported the
program already: each run is a real process (its own exit code, stdout, stderr, environment,
working directory and atexit), without the two seconds of numpy, scipy and the store's imports
that a fresh interpreter pays. One server per test process, one run at a time.

Run as a script, this file is the server: it reads one JSON request a line on stdin, forks, and
writes the child's pid, then its exit code, a line each.
"""

from __future__ import annotations

import atexit
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

PRELOAD = (
    "robocal.server.cli",
    "robocal.server.calibration.workflow",
    "robocal.server.store",
    "robocal.solver.calibrate",
    "robocal.solver.diagnose",
    "scipy.optimize",
)


def _serve() -> None:
    """The server's loop; returns in a forked child, ready to run its request."""
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    requests, replies = sys.stdin.buffer, os.fdopen(os.dup(1), "w")
    for line in requests:
        req = json.loads(line)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # the run: its own descriptors, directory and environment
            replies.close()
            null = os.open(os.devnull, os.O_RDONLY)
            os.dup2(null, 0)
            for fd, path in ((1, req["out"]), (2, req["err"])):
                f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
                os.dup2(f, fd)
                os.close(f)
            os.chdir(req["cwd"])
            os.environ.clear()
            os.environ.update(req["env"])
            sys.argv = ["robocal", *req["argv"]]
            return
        replies.write(f"{pid}\n")
        replies.flush()
        _, status = os.waitpid(pid, 0)
        replies.write(f"{os.waitstatus_to_exitcode(status)}\n")
        replies.flush()
    sys.exit(0)


class _Server:
    """The forking server of this test process, started at its first run."""

    def __init__(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, __file__], stdin=subprocess.PIPE, stdout=subprocess.PIPE, bufsize=0
        )
        self.lock = threading.Lock()
        self._buffer = b""

    def run(self, argv: list[str], cwd, timeout: float) -> subprocess.CompletedProcess:
        with self.lock, tempfile.TemporaryDirectory() as tmp:
            out, err = Path(tmp, "out"), Path(tmp, "err")
            req = {"argv": argv, "cwd": str(cwd), "env": dict(os.environ)}
            req |= {"out": str(out), "err": str(err)}
            self.proc.stdin.write((json.dumps(req) + "\n").encode())
            self.proc.stdin.flush()
            pid = int(self._line(timeout))
            try:
                code = int(self._line(timeout))
            except subprocess.TimeoutExpired:
                os.kill(pid, signal.SIGKILL)
                self._line(30)  # its exit code: the server is ready for the next run
                raise
            return subprocess.CompletedProcess(
                ["robocal", *argv], code, out.read_text(), err.read_text()
            )

    def _line(self, timeout: float) -> str:
        """The server's next reply line (read unbuffered: two may arrive at once)."""
        fd = self.proc.stdout.fileno()
        while b"\n" not in self._buffer:
            if not select.select([fd], [], [], timeout)[0]:
                raise subprocess.TimeoutExpired(["robocal"], timeout)
            chunk = os.read(fd, 4096)
            if not chunk:
                raise RuntimeError("the robocal fork server died")
            self._buffer += chunk
        line, self._buffer = self._buffer.split(b"\n", 1)
        return line.decode()


_server: _Server | None = None
_started_by = 0


def run(*args, cwd, timeout: float = 300) -> subprocess.CompletedProcess:
    """`robocal ARGS` run in cwd as its own process; its exit code, stdout and stderr."""
    global _server, _started_by
    if _server is None or _started_by != os.getpid() or _server.proc.poll() is not None:
        _server, _started_by = _Server(), os.getpid()
    return _server.run([str(a) for a in args], cwd, timeout)


def _exit_code(code) -> int:
    """The process exit code of a SystemExit's code, as the interpreter makes it."""
    if code is None or isinstance(code, int):
        return code or 0
    print(code, file=sys.stderr)
    return 1


if __name__ == "__main__":
    _serve()
    from robocal.server.cli import main  # a forked child: run its request

    try:
        code = _exit_code(main(sys.argv[1:]))
    except SystemExit as e:
        code = _exit_code(e.code)
    except BaseException:  # noqa: BLE001 - as the interpreter would: the traceback, exit 1
        sys.excepthook(*sys.exc_info())
        code = 1
    # The exit of a process: atexit and flushed streams, without tearing down the modules the
    # server imported (a few tenths of a second, and nothing a run could observe).
    threading._shutdown()  # the interpreter's first step at exit: join non-daemon threads
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
