"""Dask distributed for the batch commands: `--workers N` (a local cluster of N processes,
started and closed around the command) or `--cluster ADDRESS` (a running scheduler), and
tasks of one or more items with the outcomes handed back in item order.

Dask is an optional extra (`samba-mocap[cluster]`), imported only here and only when one
of the flags is given: a command without them starts as fast as before and runs in its own
process. A task whose worker dies is run once more on another worker
(`SCHEDULER_SETTINGS`); if that worker dies too, the items of the task are run again
one by one, and an item that kills its worker twice has a `WorkerDeathError` for outcome.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from samba.base.arguments import positive
from samba.base.errors import InputError, SambaError

INSTALL_HINT = "pip install 'samba-mocap[cluster]'"
"""What installs Dask distributed beside Samba (on the client and on every worker)."""
TASKS_PER_WORKER = 2
"""Tasks per worker thread `outcomes_in_order` makes of each window of items it groups:
enough for the workers to finish together, few enough that each task carries many
items."""
CONNECT_SECONDS = 10.0
"""How long `cluster_client` waits for a scheduler to answer, then for its first worker."""
SCHEDULER_SETTINGS = {
    "distributed.scheduler.allowed-failures": 1,
    "distributed.scheduler.worker-saturation": 1.0,
}
"""The local cluster's scheduler: a task survives one worker death (it is run again on
another worker), and a worker holds only the tasks it runs, so that a worker's death
counts against those alone. A remote scheduler's own configuration decides there."""


class WorkerDeathError(SambaError):
    """The workers that ran a task died each time (a crash, or memory running out)."""


def add_cluster_arguments(parser: argparse.ArgumentParser) -> None:
    """Add `--workers N` and `--cluster ADDRESS` (one or the other) to `parser`."""
    group = parser.add_argument_group("cluster (Dask distributed, the cluster extra)")
    choice = group.add_mutually_exclusive_group()
    choice.add_argument(
        "--workers",
        type=positive,
        metavar="WORKERS",
        help="run on a local Dask cluster of this many worker processes (default: in this process)",
    )
    choice.add_argument(
        "--cluster",
        metavar="ADDRESS",
        help="run on the Dask scheduler at ADDRESS, e.g. tcp://10.0.0.5:8786 "
        "(default: in this process)",
    )


@contextmanager
def cluster_client(workers: int | None = None, address: str | None = None) -> Iterator[Any]:
    """A Dask `Client` of a new local cluster of `workers` single-threaded processes
    (closed on exit) or of the scheduler at `address`; None (run in-process) without
    either. `InputError` naming the flag when both are given, `workers` < 1, Dask is not
    installed, or no scheduler answers at `address`, or it has no worker, within
    `CONNECT_SECONDS`."""
    if workers is None and address is None:
        yield None
        return
    flag = f"--workers {workers}" if address is None else f"--cluster {address}"
    if workers is not None and address is not None:
        raise InputError("--workers/--cluster", "give one of them, not both")
    if workers is not None and workers < 1:
        raise InputError("--workers", f"must be >= 1, got {workers}")
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise InputError(flag, f"needs Dask distributed ({exc}); {INSTALL_HINT}") from None
    if address is not None:
        try:
            client = Client(address, timeout=CONNECT_SECONDS)
        except (OSError, ValueError, TypeError) as exc:
            problem = f"no Dask scheduler answers there ({_first_line(exc)})"
            raise InputError(flag, problem) from None
        with client:
            try:
                client.wait_for_workers(1, timeout=CONNECT_SECONDS)
            except TimeoutError:
                problem = f"the scheduler has no worker; start some: dask worker {address}"
                raise InputError(flag, problem) from None
            yield client
        return
    try:
        with dask.config.set(SCHEDULER_SETTINGS):
            cluster = LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0"
            )
    except (OSError, RuntimeError) as exc:
        raise InputError(flag, f"the local cluster did not start ({_first_line(exc)})") from None
    with cluster, Client(cluster) as client:
        yield client


def outcomes_in_order(
    client: Any,
    task: Callable[..., Any],
    items: Sequence[Any],
    shared: Sequence[Any] = (),
    progress: bool | None = None,
    unit: str = "item",
    name: Callable[[Any], str] = str,
    most_per_task: int = 1,
    cost: Callable[[Any], float] | None = None,
) -> Iterator[tuple[Any, Any]]:
    """Run `task(item, *shared)` on the cluster of `client` for every item; yield (item,
    outcome) in the order of `items`, the outcome being what `task` returned or the
    exception it raised (`WorkerDeathError` naming the item by `name` when the workers
    running it died).

    Items go together in tasks of up to `most_per_task` (`_groups`): short items pay the
    scheduler's cost per task and the round trip once per group. The items are taken in
    consecutive windows of `TASKS_PER_WORKER` groups per worker thread, and a window's
    groups have similar sums of `cost(item)` (an estimate of the item's work, in any unit;
    None: 1 each) and go to the workers costliest first, so that the workers finish
    together and the outcomes of a window come back before the next window's. A group
    whose workers died is run again item by item, so that only the item that kills its
    worker fails. Each of `shared` is
    sent to every worker once, not once per task: it is a task of its own whose outcome
    workers copy from each other (run again if every copy is lost with its worker). The
    progress bar (None: on a terminal only) counts items as their tasks finish, in any
    order."""
    import dask
    from distributed import as_completed
    from tqdm import tqdm

    with dask.config.set({"distributed.admin.large-graph-warning-threshold": "1TB"}):
        sent = [client.submit(_itself, value, pure=False) for value in shared]

    pending: dict[Any, list[int]] = {}

    def submit(places: list[int]) -> Any:
        group = [items[i] for i in places]
        future = client.submit(_run_group, task, group, *sent, pure=False)
        pending[future] = places
        return future

    threads = max(1, sum(client.nthreads().values()))
    costs = [1.0] * len(items) if cost is None else [cost(item) for item in items]
    groups = _groups(costs, max(1, most_per_task), TASKS_PER_WORKER * threads)
    running = as_completed([submit(places) for places in groups])
    finished: dict[int, Any] = {}
    following = 0
    bar = tqdm(total=len(items), unit=unit, disable=None if progress is None else not progress)
    try:
        for future in running:
            places = pending.pop(future)
            outcomes = _group_outcomes(future, len(places))
            if outcomes is None and len(places) > 1:
                for i in places:
                    running.add(submit([i]))
                continue
            if outcomes is None:
                problem = "the worker running it died each time it was tried"
                outcomes = [WorkerDeathError(f"{name(items[places[0]])}: {problem}")]
            bar.update(len(places))
            finished.update(zip(places, outcomes, strict=True))
            while following in finished:
                yield items[following], finished.pop(following)
                following += 1
    finally:  # also when the caller stops early, maybe after the client has closed
        bar.close()
        if pending and client.status == "running":
            client.cancel(list(pending))


def _groups(costs: Sequence[float], most: int, per_window: int) -> list[list[int]]:
    """The places of items of estimated `costs` in groups of up to `most`, in the order to
    run them. The items are taken in consecutive windows of `per_window * most`, each
    split into `per_window` groups (one per item when it holds fewer) by the greedy
    largest-first rule: item by item, costliest first, into the group of the smallest
    sum that is not full. A window's groups come costliest first, each group's places in
    item order."""
    order: list[list[int]] = []
    span = per_window * most
    for start in range(0, len(costs), span):
        window = range(start, min(start + span, len(costs)))
        places: list[list[int]] = [[] for _ in range(min(per_window, len(window)))]
        sums = [0.0] * len(places)
        for i in sorted(window, key=lambda i: -costs[i]):  # stable: ties in item order
            g = min((g for g in range(len(places)) if len(places[g]) < most), key=sums.__getitem__)
            places[g].append(i)
            sums[g] += costs[i]
        ranked = sorted(range(len(places)), key=lambda g: -sums[g])
        order.extend(sorted(places[g]) for g in ranked)
    return order


def _run_group(task: Callable[..., Any], group: Sequence[Any], *shared: Any) -> list[Any]:
    """`task(item, *shared)` for every item of `group`: what it returned or raised."""
    outcomes = []
    for item in group:
        try:
            outcomes.append(task(item, *shared))
        except Exception as exc:
            outcomes.append(exc)
    return outcomes


def _group_outcomes(future: Any, count: int) -> list[Any] | None:
    """The outcomes of the `count` items of a finished group task; None when the workers
    running it died (Dask's `KilledWorker`); the task's own error for each item when it
    failed as a whole (its outcomes could not be sent back, say)."""
    from distributed import KilledWorker

    try:  # waits while a result lost with its worker is computed again
        outcomes = future.result()
    except KilledWorker:
        return None
    except Exception as exc:
        return [exc] * count
    finally:
        future.release()
    return list(outcomes)


def _itself(value: Any) -> Any:
    """`value`: the task that holds a value `outcomes_in_order` shares."""
    return value


def _first_line(exc: BaseException) -> str:
    """The first line of an error's text (Dask's connection errors run over several)."""
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]
