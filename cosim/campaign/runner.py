"""One campaign run, supervised: its run function loaded, its ``prepare`` and ``validate`` hooks, the run in a
forked child (cosim/supervise.py) and its record, whichever executor runs it (cosim/campaign/execute.py in this
process or a pool worker, cosim/campaign/zygote.py on a Dask worker)."""
from __future__ import annotations

import importlib
import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from feeddrive.cosim.campaign.schema import CampaignError, RunSpec
from feeddrive.cosim.component import legacy_hint


def resolve_function(spec: str) -> Callable[[RunSpec], dict]:
    """Import ``package.module:function``."""
    module_name, _, name = spec.partition(":")
    try:
        fn = getattr(importlib.import_module(module_name), name)
    except (ImportError, AttributeError) as exc:
        raise CampaignError(f"run: cannot load {spec!r} ({exc}){legacy_hint(module_name)}") from None
    if not callable(fn):
        raise CampaignError(f"run: {spec!r} is not callable")
    return fn


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"run result holds a {type(obj).__name__}, which is not JSON-serialisable")


def _call(fn: Callable[[RunSpec], dict], spec: RunSpec) -> str:
    """In the supervised child: the run's result as JSON text (a str pickles fast and always)."""
    return json.dumps(fn(spec), default=_jsonable)


def execute(run: str | Callable[[RunSpec], dict], spec: RunSpec, timeout: float | None = None) -> dict[str, Any]:
    """Run one spec in a supervised child process and return its record; never raises for the run's sake.

    The run function's optional ``prepare()`` runs first, here (e.g. the imports of every run, done
    once per worker process). A run that raises, crashes (an FMU's segmentation fault kills only the child), hangs (a call over
    its ``plant.call_timeout``, or the whole run over ``timeout`` seconds) becomes a ``failed`` record
    with its reason. The result goes through a JSON round trip in the child, so records are identical
    whichever executor ran them.
    """
    from feeddrive.cosim.supervise import reap, supervise

    start = time.perf_counter()
    result, status, reason = None, "failed", ""
    reap()  # the earlier runs' children that have exited, where no thread reaps them (supervise.REAP_IN_THREAD)
    try:
        fn = resolve_function(run) if isinstance(run, str) else run
        prepare = getattr(fn, "prepare", None)
        if callable(prepare):  # imports done once in this worker, not again in every forked child
            prepare()
        check = getattr(fn, "validate", None)
        if callable(check):  # the scenario resolved here too: its FMU's description and units are then
            check(spec)      # read once per worker and inherited by the run's child (a failure is the run's)
        outcome = supervise(_call, fn, spec, timeout=timeout)
        if outcome.status == "ok":
            result, status = json.loads(outcome.value), "ok"
        elif outcome.status == "error":
            exc = outcome.error
            if not isinstance(exc, Exception):  # Ctrl-C in the run stops the campaign, as without a child
                raise exc
            reason = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        else:
            reason = f"{outcome.status}: {outcome.describe()}"
    except Exception as exc:  # a failing run must not stop the campaign: it is recorded with its reason
        reason = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    return {"id": spec.id, "index": spec.index, "seed": spec.seed, "overrides": spec.overrides,
            "status": status, "reason": reason, "elapsed_s": time.perf_counter() - start, "result": result}


#: this process's BLAS libraries (``threadpoolctl.ThreadpoolController``), found once its run function is prepared
_BLAS: list[Any] = []


def one_blas_thread() -> Any:
    """This process's BLAS libraries (numpy's and scipy's OpenBLAS) on one thread: now, and until the returned
    limiter is left (``with one_blas_thread(): ...``; a campaign's worker process, which is the campaign's, keeps it).

    The ``cosim`` command sets one thread before numpy loads (cosim/cli ``BLAS_THREADS``); a campaign started from
    Python, in a process whose numpy runs several, runs its runs with one (each forked from a process that has
    it: the caller's, within its loop; a pool worker or a Dask worker's zygote, for good): OpenBLAS's threads spin
    while they wait for one another, and 2 workers with 2 threads each were 1.13 times one worker (1.9 with one
    each, issue 26). Switching the threads at each run cost the caller ~20 ms of CPU a run.
    """
    if not _BLAS:
        from threadpoolctl import ThreadpoolController

        _BLAS.append(ThreadpoolController())  # after prepare: the libraries the runs use are loaded
    return _BLAS[0].limit(limits=1, user_api="blas")


def _lost(spec: RunSpec, reason: str) -> dict[str, Any]:
    """The record of a run whose worker process died under it (not retried: it may die again)."""
    return {"id": spec.id, "index": spec.index, "seed": spec.seed, "overrides": spec.overrides,
            "status": "failed", "reason": reason, "elapsed_s": None, "result": None}
