"""Killable worker processes: one per job or heavy request, forked from the fork server, each on
a lifeline to the service so that none outlives it, each stopped alone without touching others.

A child runs `target(*args, report)` and sends back ("result", value) or ("error", exception)
over its own pipe; `report(message)` sends ("report", message) on the way. The numerics run
outside the service's process, so a hung LAPACK call or a runaway fit costs one process, which
the service kills at its wall-clock limit; the API, the e-stop and the other jobs never wait.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import threading
import time
from multiprocessing.connection import Connection
from typing import Final

# Not fork: the service has threads (uvicorn, the acquisition, the event bus) whose locks a
# forked child would inherit held. The fork server is a single-threaded process that imports
# the modules below once (the solver, matplotlib, rerun for the recordings); children forked from
# it start in milliseconds with them loaded, as a job gets a fresh process each time.
START_METHOD: Final = "forkserver"
PRELOAD = [
    "robocal.server.service.worker",
    "robocal.server.figures.charts",
    "robocal.server.recordings.calibration",
    "robocal.server.acquisition.campaigns",
]
# Jobs are batch work: the API and a running acquisition (a robot and a tracker waiting on it)
# get the CPU first.
NICENESS = 10
REASON_CHARS = 500
JOIN_S = 2.0

_context = multiprocessing.get_context(START_METHOD)
_context.set_forkserver_preload(PRELOAD)  # no effect once the fork server runs


class WorkerDied(RuntimeError):
    """The child ended without an answer (killed, or crashed in native code)."""


def one_line(e: BaseException) -> str:
    """A failure reason: the exception's type and message on one line, never a traceback."""
    text = " ".join(str(e).split())
    text = f"{type(e).__name__}: {text}" if text else type(e).__name__
    return text if len(text) <= REASON_CHARS else text[: REASON_CHARS - 3] + "..."


def exit_reason(code: int | None) -> str:
    """How a process ended, in words: "killed by SIGKILL", "exit code 1"."""
    if code is None:
        return "still running"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


def warm_up() -> None:
    """Start the fork server and wait for it to import PRELOAD (seconds), by running one child,
    so that the first job or request does not pay for it."""
    try:
        call(_nothing, (), timeout=600, name="robocal-warm-up")
    except Exception:  # noqa: BLE001 - a failure here shows again, named, at the first job
        pass


def _nothing(report=None) -> None:
    """A child that does nothing (warm_up's)."""


class Child:
    """One worker process running target(*args, report) with its answer pipe and lifeline."""

    def __init__(self, target, args: tuple, name: str = "robocal-worker"):
        # Two one-way pipes: answers come up one; the other's write end stays here only, so
        # the child reads end-of-file the moment the service exits, however it exits.
        self.answers, answer_end = _context.Pipe(duplex=False)
        lifeline_end, self._lifeline = _context.Pipe(duplex=False)
        self.process = _context.Process(
            target=_main, name=name, daemon=True, args=(target, args, answer_end, lifeline_end)
        )
        try:
            self.process.start()
        finally:
            answer_end.close()
            lifeline_end.close()
        self.started = time.monotonic()
        self.ended = False  # its answer pipe reached end-of-file

    @property
    def pid(self) -> int | None:
        return self.process.pid

    @property
    def sentinel(self) -> int:
        return self.process.sentinel

    def messages(self) -> list[tuple[str, object]]:
        """Every message the child has sent so far (without waiting)."""
        out = []
        try:
            while not self.ended and self.answers.poll(0):
                out.append(self.answers.recv())
        except (EOFError, OSError):
            self.ended = True  # the child closed its end and everything it sent has been read
        return out

    def kill(self) -> None:
        """SIGKILL: a native loop does not run Python signal handlers, so nothing gentler."""
        try:
            self.process.kill()
        except (AttributeError, ValueError):
            pass  # never started, or already closed

    def reap(self, timeout: float = JOIN_S) -> int | None:
        """Wait for the process to end (killing it if it outlives timeout); its exit code."""
        self.process.join(timeout)
        if self.process.exitcode is None:
            self.kill()
            self.process.join(timeout)
        code = self.process.exitcode
        self.answers.close()
        self._lifeline.close()
        return code


def call(
    target,
    args: tuple,
    timeout: float,
    name: str = "robocal-call",
    children: set | None = None,
    lock: threading.Lock | None = None,
):
    """target(*args, report) in a child; its result, or its exception re-raised here.

    TimeoutError after `timeout` s (the child is killed); WorkerDied if it died without an
    answer. `children` (guarded by `lock`) holds the child while it runs, for a shutdown to kill.
    """
    guard = lock if lock is not None else threading.Lock()
    child = Child(target, args, name)
    if children is not None:
        with guard:
            children.add(child)
    try:
        deadline = child.started + timeout
        while True:
            left = deadline - time.monotonic()
            try:
                ready = child.answers.poll(max(left, 0))
                kind, value = child.answers.recv() if ready else (None, None)
            except (EOFError, OSError):
                child.reap()
                raise WorkerDied(
                    f"the worker process ended without an answer "
                    f"({exit_reason(child.process.exitcode)})"
                ) from None
            if kind is None:
                raise TimeoutError(f"exceeded its wall-clock limit of {timeout:g} s")
            if kind != "report":
                break
    finally:
        child.kill()
        child.reap()
        if children is not None:
            with guard:
                children.discard(child)
    if kind == "error":
        assert isinstance(value, BaseException)  # the child sends its exception as it is
        raise value
    return value


# --- in the child -------------------------------------------------------------------------------


def _main(target, args: tuple, answers: Connection, lifeline: Connection) -> None:
    # Ctrl-C is the service's to handle: it ends its workers itself on the way out.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.nice(NICENESS)
    threading.Thread(target=_exit_with_service, args=(lifeline,), daemon=True).start()

    def report(message) -> None:
        answers.send(("report", message))

    try:
        answer = ("result", target(*args, report))
    except Exception as e:  # noqa: BLE001 - the caller decides what the failure means
        answer = ("error", _portable(e))
    try:
        answers.send(answer)
    except (pickle.PicklingError, TypeError, AttributeError) as e:
        answers.send(("error", RuntimeError(one_line(e))))
    answers.close()


def _portable(e: Exception) -> Exception:
    # The exception itself when it survives the trip (its type says 404, 409 or 422), else its
    # one-line description.
    try:
        pickle.loads(pickle.dumps(e))
        return e
    except Exception:  # noqa: BLE001 - any exception may refuse to pickle its own way
        return RuntimeError(one_line(e))


def _exit_with_service(lifeline: Connection) -> None:
    # The service holds the only write end: end-of-file means it exited (or was killed), and a
    # worker must not outlive it and write to the store of a service that has restarted since.
    try:
        lifeline.recv_bytes()
    except (EOFError, OSError):
        pass
    os._exit(1)
