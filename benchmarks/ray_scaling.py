"""The full WANDR grid fanned out over 1 and over 2 local Ray workers (`motion-envs bench ray-scaling`).

Runs every row of `motion-envs bench wandr` (its 3,750-rollout grid, the latent-optimisation rows included)
as Ray tasks (`benchmarks.fanout`) on a local Ray given 1 CPU, then on one given 2 CPUs (one task per CPU,
one torch thread per task), in the same run: the ratio of the two wall times is the scale-out on this
machine. Both tables are compared with each other and with `benchmarks/results/wandr_grid.md` (the
single-process run, written by `motion-envs bench wandr` on the same weights), row by row, on SR, FS and DTG
as the table prints them. Writes the section "Benchmarks on Ray" of `benchmarks/results/rllib.md`.
"""

from __future__ import annotations

import time
from pathlib import Path

from benchmarks import wandr_grid
from benchmarks.machine import machine_line
from benchmarks.sections import replace_section

RESULTS = Path(__file__).resolve().parent / "results"


def table_cells(rows: dict[str, dict]) -> dict[str, str]:
    """{label: "SR | FS | DTG"} as the table prints them (the time column left out)."""
    return {label: " | ".join(wandr_grid.table_row(label, row).split(" | ")[1:4]) for label, row in rows.items()}


def single_process_cells(path: Path) -> dict[str, str]:
    """The same cells read from a written `wandr_grid.md`."""
    cells = {}
    for line in path.read_text().splitlines():
        parts = [part.strip() for part in line.strip("|").split("|")]
        if line.startswith("| ") and len(parts) == 5 and parts[1] and not parts[0].startswith(("row", "---")):
            cells[parts[0]] = " | ".join(parts[1:4])
    return cells


def main() -> int:
    import ray

    rows = wandr_grid.grid_rows(quick=False)
    timings, tables = {}, {}
    for cpus in (1, 2):
        ray.init(num_cpus=cpus, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
        began = time.perf_counter()
        tables[cpus] = table_cells(wandr_grid.run_rows(rows, seed=0, ray_address="local"))
        timings[cpus] = time.perf_counter() - began
        ray.shutdown()
    single = RESULTS / "wandr_grid.md"
    reference = single_process_cells(single) if single.exists() else {}
    differing = [label for label in tables[1] if tables[1][label] != tables[2][label]]
    versus_single = [label for label in tables[2] if label in reference and reference[label] != tables[2][label]]
    tasks = sum(len(row.shards()) for row in rows.values())
    lines = ["## Benchmarks on Ray", "", machine_line(), "",
             f"`motion-envs bench ray-scaling`: every row of the full WANDR grid ({len(rows)} rows, {tasks} tasks of ≤ "
             f"{wandr_grid.SHARD} rollouts) on a local Ray with 1 CPU, then with 2 (one task, one torch thread per CPU).", "",
             "| workers | wall time (s) | speed-up |", "|---|---|---|",
             f"| 1 | {timings[1]:.0f} | 1.00× |", f"| 2 | {timings[2]:.0f} | {timings[1] / timings[2]:.2f}× |", "",
             f"Tables of 1 and 2 workers: {'identical' if not differing else 'differ in ' + ', '.join(differing)} "
             f"(SR, FS, DTG of {len(tables[1])} rows).",
             f"Against the single-process table (`{single.name}`, `motion-envs bench wandr`): "
             + ("not found" if not reference else "identical" if not versus_single else "differ in " + ", ".join(versus_single))
             + f" ({len([label for label in tables[2] if label in reference])} rows compared).", ""]  # fmt: skip
    section = "\n".join(lines)
    print(section)
    replace_section(RESULTS / "rllib.md", section, title="# Ray and RLlib")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
