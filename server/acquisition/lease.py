"""One process drives a campaign: a lease in the store, renewed by a timer while the run lasts.

A killed owner stops renewing, so its claim lapses after LEASE_S; a holder on this host whose
process is gone is taken over at once.
"""

from __future__ import annotations

import os
import secrets
import socket
import threading

from robocal.server import store

LEASE_S = 30.0
# Renewed this often: two renewals may fail (a busy database) before the claim lapses.
RENEW_EVERY_S = LEASE_S / 6


def process_owner() -> str:
    """This process's owner id: host:pid:random (random: two owners in one process differ)."""
    return f"{socket.gethostname()}:{os.getpid()}:{secrets.token_hex(4)}"


def is_dead(owner: str | None) -> bool:
    """True if `owner` is a process of this host that no longer exists."""
    host, _, rest = (owner or "").partition(":")
    pid = rest.partition(":")[0]
    if host != socket.gethostname() or not pid.isdigit() or int(pid) == os.getpid():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:  # alive, another user's
        return False
    return False


def claim(db: store.Database, campaign_id: int, owner: str, ttl_s: float = LEASE_S) -> None:
    """Take the campaign for `owner` (LeaseHeld if another live process has it)."""
    holder = store.get_campaign(db, campaign_id=campaign_id).lease_owner
    store.take_lease(
        db,
        campaign_id=campaign_id,
        owner=owner,
        ttl_s=ttl_s,
        dead_owner=holder if holder != owner and is_dead(holder) else None,
    )


class Lease:
    """The claim on a campaign while a run lasts: taken at start, renewed on a timer thread,
    released at the end; on_lost() is called if another process took it (we stalled past it)."""

    def __init__(
        self,
        db: store.Database,
        campaign_id: int,
        owner: str,
        *,
        ttl_s: float = LEASE_S,
        every_s: float = RENEW_EVERY_S,
        on_lost=None,
        log=None,
    ):
        self.db, self.campaign_id, self.owner = db, campaign_id, owner
        self.ttl_s, self.every_s = ttl_s, every_s
        self.on_lost = on_lost or (lambda: None)
        self.log = log or (lambda msg: None)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def __enter__(self) -> Lease:
        claim(self.db, self.campaign_id, self.owner, self.ttl_s)
        self._thread = threading.Thread(
            target=self._renew, daemon=True, name=f"robocal-lease-{self.campaign_id}"
        )
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        try:
            store.release_lease(self.db, campaign_id=self.campaign_id, owner=self.owner)
        except store.StoreError:
            pass

    def _renew(self) -> None:
        while not self._stop.wait(self.every_s):
            try:
                held = store.renew_lease(
                    self.db, campaign_id=self.campaign_id, owner=self.owner, ttl_s=self.ttl_s
                )
            except Exception as e:  # noqa: BLE001 - a busy database: try again next time
                self.log(f"lease of campaign {self.campaign_id} not renewed: {e}")
                continue
            if not held:
                self.log(f"campaign {self.campaign_id}: another process took it over")
                self.on_lost()
                return
