"""Compare the railway scenario's results of a local run and a container run (the container
checks): ``python3 scripts/compare-runs.py CHECK LOCAL_DIR CONTAINER_DIR``.

Both runs must have results.csv and summary.json with status completed, and the sequence of
changes of (TrackBalises.last_balise_id, TrackBalises.balises_passed) must be equal. Exits 1
naming the first difference. Plain python3 (no project packages): it runs before any set-up.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

COLUMNS = ("TrackBalises.last_balise_id", "TrackBalises.balises_passed")


def load(check: str, folder: Path) -> tuple[list[tuple[str, ...]], list[tuple[str, ...]]]:
    """(the two columns of every row, the balise sequence: each change with its time)."""
    for name in ("results.csv", "summary.json"):
        if not (folder / name).is_file():
            sys.exit(f"{check}: {folder / name} is missing")
    summary = json.loads((folder / "summary.json").read_text())
    if summary.get("status") != "completed":
        sys.exit(
            f"{check}: {folder}: status {summary.get('status')!r}, reason {summary.get('reason')!r}"
        )
    with (folder / "results.csv").open(newline="") as file:
        rows = list(csv.DictReader(file))
    missing = [c for c in COLUMNS if rows and c not in rows[0]]
    if not rows or missing:
        sys.exit(f"{check}: {folder}/results.csv has no rows or lacks {missing}")
    columns = [tuple(r[c] for c in COLUMNS) for r in rows]
    sequence: list[tuple[str, ...]] = []
    last = None
    for row, value in zip(rows, columns, strict=True):
        if value != last:
            sequence.append((row["time"], *value))
            last = value
    return columns, sequence


def main(check: str, local: Path, container: Path) -> None:
    local_columns, local_seq = load(check, local)
    container_columns, container_seq = load(check, container)
    passed = int(local_seq[-1][2] or 0)
    print(
        f"{check}: local run: {len(local_columns)} rows, {passed} balises passed; "
        f"container run: {len(container_columns)} rows, {container_seq[-1][2]} passed"
    )
    if passed == 0:
        sys.exit(f"{check}: the local run passed no balise; nothing to compare")
    if [s[1:] for s in local_seq] != [s[1:] for s in container_seq]:
        for i, (a, b) in enumerate(zip(local_seq, container_seq, strict=False)):
            if a[1:] != b[1:]:
                sys.exit(
                    f"{check}: balise sequences differ at reading {i}: local (time, id, passed) "
                    f"{a} vs container {b} ({len(local_seq)} vs {len(container_seq)})"
                )
        sys.exit(
            f"{check}: balise sequences differ in length: {len(local_seq)} local vs "
            f"{len(container_seq)} container readings"
        )
    same_times = local_seq == container_seq and local_columns == container_columns
    print(
        f"{check}: the same balise sequence ({len(local_seq) - 1} readings, "
        f"ids {local_seq[1][1]} .. {local_seq[-1][1]})"
        + ("; identical at every step" if same_times else "; passage times differ")
    )


if __name__ == "__main__":
    main(sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]))
