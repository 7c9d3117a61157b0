"""The event bus: fans events out from worker threads to asyncio subscribers (the SSE streams)."""

from __future__ import annotations

import asyncio
import datetime as dt
import itertools
import threading

# Past this many unread events a slow subscriber loses the oldest rather than holding memory.
QUEUE_SIZE = 1000


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


class Events:
    """Fans events out from worker threads to asyncio subscribers (the SSE streams)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._subscribers: set[tuple[asyncio.AbstractEventLoop, asyncio.Queue]] = set()
        self._ids = itertools.count(1)

    def subscribe(self) -> asyncio.Queue:
        """A queue of (id, event) for the calling event loop; unsubscribe() it when done."""
        queue: asyncio.Queue = asyncio.Queue(QUEUE_SIZE)
        with self._lock:
            self._subscribers.add((asyncio.get_running_loop(), queue))
        return queue

    def unsubscribe(self, queue: asyncio.Queue) -> None:
        with self._lock:
            self._subscribers = {(loop, q) for loop, q in self._subscribers if q is not queue}

    def publish(self, event: dict) -> None:
        """Send an event (a dict with a "type") to every subscriber; safe from any thread."""
        with self._lock:
            item = (next(self._ids), dict(event, time=_now().isoformat()))
            subscribers = list(self._subscribers)
        for loop, queue in subscribers:
            try:
                loop.call_soon_threadsafe(_put, queue, item)
            except RuntimeError:  # that loop has closed: its stream is gone
                self.unsubscribe(queue)

    def close(self) -> None:
        """End every stream (at shutdown)."""
        with self._lock:
            subscribers, self._subscribers = list(self._subscribers), set()
        for loop, queue in subscribers:
            try:
                loop.call_soon_threadsafe(_put, queue, None)
            except RuntimeError:
                pass


def _put(queue: asyncio.Queue, item) -> None:
    if queue.full():
        queue.get_nowait()  # drop the oldest: a stalled client must not stall the workers
    queue.put_nowait(item)
