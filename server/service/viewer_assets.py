"""Rerun's web viewer (its JavaScript and WebAssembly) taken from the installed rerun-sdk, kept
on disk per rerun version so the service can serve it itself and the page works offline."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

# What the viewer needs: its wasm-bindgen glue and the module (the page around it is ours,
# web/viewer.html: rerun's own index.html loads a font from Google).
ASSETS = ("re_viewer.js", "re_viewer_bg.wasm")
EXTRACT_TIMEOUT_S = 120.0
_lock = threading.Lock()


class ViewerUnavailable(RuntimeError):
    """The installed rerun-sdk did not give its web viewer (the message says why)."""


def rerun_version() -> str:
    from importlib.metadata import version

    return version("rerun-sdk")


def viewer_dir(cache_root: Path) -> Path:
    """The directory holding ASSETS for the installed rerun-sdk, extracted on first use."""
    dest = Path(cache_root) / rerun_version()
    if _complete(dest):
        return dest
    with _lock:  # two first requests at once extract once
        if not _complete(dest):
            _extract(dest)
    return dest


def _complete(dest: Path) -> bool:
    return all((dest / name).is_file() for name in ASSETS)


def _extract(dest: Path) -> None:
    """Run rerun's own web-viewer server in a child process just long enough to copy ASSETS.

    The assets are compiled into rerun's extension module and only its server hands them out;
    a child process, because that server cannot be stopped and listens on every interface
    (for the second or so this takes; what it serves is public code, no cell data).
    """
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".viewer-", dir=dest.parent))
    try:
        env = {**os.environ, "RERUN_ANALYTICS": "0"}
        cmd = [sys.executable, "-m", "robocal.server.service.viewer_assets", str(tmp)]
        done = subprocess.run(
            cmd, env=env, capture_output=True, text=True, timeout=EXTRACT_TIMEOUT_S
        )
        if done.returncode != 0 or not _complete(tmp):
            why = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
            raise ViewerUnavailable(f"rerun-sdk {rerun_version()} gave no web viewer: {why[0]}")
        if dest.exists():
            shutil.rmtree(dest)
        tmp.rename(dest)
    except subprocess.TimeoutExpired as e:
        raise ViewerUnavailable(f"rerun's web viewer did not start within {e.timeout:g} s") from e
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _copy_assets(dest: Path) -> None:
    """In the child: start rerun's web-viewer server and save ASSETS from it into dest."""
    import rerun as rr

    port = _free_port()
    rr.serve_web_viewer(web_port=port, open_browser=False)
    deadline = time.monotonic() + EXTRACT_TIMEOUT_S
    for name in ASSETS:
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/{name}", timeout=30) as r:
                    data = r.read()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)  # the server thread is still binding
        (dest / name).write_bytes(data)


if __name__ == "__main__":
    _copy_assets(Path(sys.argv[1]))
    # rerun's server thread never ends; leave without waiting for it
    sys.stdout.flush()
    os._exit(0)


__all__ = ["ASSETS", "ViewerUnavailable", "viewer_dir"]
