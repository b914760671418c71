"""A benchmark's episodes as independent tasks: run in this process, or fanned out over a Ray cluster.

A benchmark splits its protocol into tasks of fixed size (e.g. 250 rollouts of one table row) and calls
`run_tasks(function, tasks, ray_address)`; the results come back in task order, wherever they ran, and the
benchmark merges them into its table. Because the split is the same in both modes and every task draws its
own noise per body (`motion_envs.counter_random.BodyNoise`), a fanned-out run computes exactly what the
single-process run computes, given the same torch thread count per task (the last bits of a float reduction
can depend on it: Ray gives each task `num_cpus` = 1 thread).

    motion-envs bench wandr --ray            # a local Ray on this machine, one task per core
    motion-envs bench wandr --ray auto       # the cluster this machine joined (`ray start --address ...`)

A task whose worker dies (killed, out of memory, a lost node) is retried by Ray (`max_retries`), so the table
is still complete; a task that raises fails the run with its exception.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from typing import Any

from tqdm import tqdm

LOCAL = "local"
"""`ray_address` for a Ray started on this machine (bound to 127.0.0.1, no dashboard)."""
MAX_RETRIES = 3


def call(function: Callable[..., Any], *arguments: Any) -> Any:
    """`function(*arguments)`: the Ray task body, so that any picklable callable can be a benchmark's task."""
    return function(*arguments)


def run_tasks(function: Callable[..., Any], tasks: Sequence[tuple], ray_address: str | None = None,
              description: str = "tasks", cpus_per_task: float = 1.0) -> list[Any]:  # fmt: skip
    """`[function(*task) for task in tasks]`, in this process (`ray_address` None) or as Ray tasks.

    function: a picklable callable (a module-level function: Ray workers import it by name). ray_address: None, `LOCAL`, or the
    address of a running cluster ("auto", "host:6379", "ray://host:10001"). Shows tasks done."""
    if ray_address is None:
        return [function(*task) for task in tqdm(tasks, desc=description, unit="task")]
    import ray

    if not ray.is_initialized():
        if ray_address == LOCAL:
            ray.init(include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
        else:
            ray.init(address=ray_address, log_to_driver=False)
    remote = ray.remote(num_cpus=cpus_per_task, max_retries=MAX_RETRIES, retry_exceptions=False)(call)
    pending = {remote.remote(function, *task): index for index, task in enumerate(tasks)}
    results: list[Any] = [None] * len(tasks)
    with tqdm(total=len(tasks), desc=f"{description} (ray)", unit="task") as bar:
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for reference in done:
                results[pending.pop(reference)] = ray.get(reference)
                bar.update()
    return results


def spans(count: int, size: int) -> list[tuple[int, int]]:
    """[first, last) ranges of at most `size` items covering 0..count-1: a protocol's fixed split."""
    return [(first, min(first + size, count)) for first in range(0, count, size)]


def group_seed(seed: int, first: int) -> int:
    """The seed of the task whose items start at `first`: the same wherever the task runs."""
    return seed * 1_000_003 + first


def run_grouped(function: Callable[..., Any], tasks: Sequence[tuple[Hashable, tuple]], ray_address: str | None = None,
                description: str = "tasks") -> dict[Hashable, list[Any]]:  # fmt: skip
    """`run_tasks` over `(key, arguments)` pairs; the results of each key (e.g. a table row) in task order, keys in
    the order they first appear."""
    results = run_tasks(function, [arguments for _, arguments in tasks], ray_address, description)
    grouped: dict[Hashable, list[Any]] = {}
    for (key, _), result in zip(tasks, results):
        grouped.setdefault(key, []).append(result)
    return grouped
