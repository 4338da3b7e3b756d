"""The records of a campaign's Dask tasks, received as each run ends (cosim/campaign/execute.py ``_dask``).

A task holds several runs (``execute.batches``); ``zygote.run_batch`` publishes each run's record as it ends, an
event of the campaign's own topic (``Worker.log_event``), which the scheduler forwards to the campaign's client.
The campaign writes it then, not when the whole task ends: Ctrl-C (which stops a ``local_cluster``'s workers too)
loses only the runs in progress, and the progress bar moves run by run.
"""
from __future__ import annotations

import collections
import json
import uuid
from collections.abc import Callable, Iterator
from typing import Any

#: the most records this campaign leaves stored on the scheduler (its topic's events, already received here):
#: beyond, they are dropped there (``prune``), where a campaign of large records (many motions) held up to 1000
KEPT = 64


class Arrivals:
    """The records a campaign's Dask tasks publish as each run ends (``zygote.run_batch``), received here.

    The client calls ``arrive`` in its event loop's thread; the campaign's thread takes them in ``wait`` (as the
    tasks complete) and ``drain``. ``recorded`` holds the ids of the runs recorded so far.
    """

    def __init__(self, client: Any) -> None:
        self.client, self.topic, self.recorded = client, f"feeddrive-campaign-{uuid.uuid4().hex}", set()
        self.records: collections.deque[str] = collections.deque()
        self.pending: Any = None
        self.pruned = 0  # len(recorded) at the last prune
        client.subscribe_topic(self.topic, self.arrive)

    def arrive(self, event: tuple[float, str]) -> None:
        """In the client's event loop: one run's record (JSON text); wakes the campaign's thread."""
        self.records.append(event[1])
        condition = getattr(self.pending, "thread_condition", None)
        if condition is not None:
            with condition:
                condition.notify_all()

    def completed(self, futures: list) -> Any:
        from distributed import as_completed

        self.pending = as_completed(futures)
        return self.pending

    def drain(self) -> list[dict]:
        """The records arrived since the last call, in their order."""
        out = []
        while self.records:
            out.append(json.loads(self.records.popleft()))
        return out

    def wait(self, pending: Any, arrived: Callable[[dict], None],
             idle: Callable[[], None] | None = None) -> Iterator[Any]:
        """The tasks of ``pending`` as they complete; ``arrived(record)`` for each published record meanwhile, and
        ``idle()`` each time nothing came for a while (``NoWorkers.check``)."""
        condition = getattr(pending, "thread_condition", None)
        while True:
            for rec in self.drain():
                arrived(rec)
            ready = pending.next_batch(block=False) if pending.has_ready() else []
            if ready:
                yield from ready
            elif pending.is_empty():
                return
            elif condition is None:
                yield next(pending)
            else:
                with condition:  # notified by a task's completion and by ``arrive``; the timeout is a safety net
                    if not self.records and not pending.has_ready() and not condition.wait(timeout=0.5) and idle:
                        idle()

    def prune(self) -> None:
        """Drop the events the scheduler keeps of this topic once ``KEPT`` more were recorded (a round trip)."""
        if len(self.recorded) - self.pruned < KEPT:
            return
        self.pruned = len(self.recorded)
        try:
            self.client.run_on_scheduler(_forget_topic, self.topic, True)
        except Exception:  # noqa: BLE001, S110 - a busy or unreachable scheduler: dropped at the end, or never
            pass

    def close(self) -> None:
        """Stop receiving, and drop the topic's events the scheduler kept (a long-lived one would keep them all)."""
        try:
            self.client.unsubscribe_topic(self.topic)
            self.client.run_on_scheduler(_forget_topic, self.topic)
        except Exception:  # noqa: BLE001, S110 - a closing or unreachable scheduler: nothing left to stop
            pass


#: seconds between two looks at the cluster's workers while no record comes (``NoWorkers``)
NO_WORKER_CHECK_S = 5.0


class NoWorkers:
    """Says on stderr when the campaign's cluster has had no worker for ``NO_WORKER_CHECK_S``: its tasks wait for
    one to join (Dask's way), where the campaign sat silent (a cluster whose workers were killed, or never came).
    Said once, and again after a worker came and went."""

    def __init__(self, client: Any, scheduler: str, recorded: Callable[[], int], total: int) -> None:
        import time

        self.client, self.scheduler, self.recorded, self.total = client, scheduler, recorded, total
        self.clock, self.last, self.since, self.said = time.monotonic, time.monotonic(), None, False

    def check(self) -> None:
        """Look at the workers (a round trip to the scheduler) once every ``NO_WORKER_CHECK_S``."""
        import sys

        now = self.clock()
        if now - self.last < NO_WORKER_CHECK_S:
            return
        self.last = now
        try:
            workers = len(self.client.nthreads())
        except Exception:  # noqa: BLE001 - the scheduler unreachable: the client says so itself (SchedulerLost)
            return
        if workers:
            self.since, self.said = None, False
            return
        self.since = now if self.since is None else self.since
        if not self.said and now - self.since >= NO_WORKER_CHECK_S:
            self.said = True
            print(f"cosim campaign: the Dask scheduler {self.scheduler} has had no worker for "
                  f"{NO_WORKER_CHECK_S:g} s: the runs wait for one to join ({self.recorded()} of {self.total} "
                  "recorded so far; Ctrl-C keeps them, and the same command runs the others)", file=sys.stderr)


def _forget_topic(topic: str, keep_subscribers: bool = False, dask_scheduler: Any = None) -> None:
    """On the scheduler: forget the events of ``topic`` (a campaign's records, already received); with
    ``keep_subscribers`` only its events (the campaign goes on), else the topic."""
    topics = getattr(getattr(dask_scheduler, "_broker", None), "_topics", None)
    if not isinstance(topics, dict) or topic not in topics:
        return
    if keep_subscribers:
        topics[topic].events.clear()
    else:
        topics.pop(topic)
