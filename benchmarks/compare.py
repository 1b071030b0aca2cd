"""Two trees' benchmark sections in turns, in one run: ``before`` and ``after`` (each a checkout
set up with ``make setup``) run the same sections of their own ``benchmarks/suite.py`` one after
the other, ``--rounds`` times, so that a busy moment hits both alike; the table gives each row's
median Coupler figure in both and their ratio (after / before), with the spread of each tree's
rounds beside it, which is what a ratio must clear to be more than noise.

    .venv/bin/python benchmarks/compare.py --before ../old-checkout --sections chains,remotes

Rows are matched by case and reference; a row only one tree has is listed with the tree that
has it.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_sections(tree: Path, sections: str, out: Path) -> dict[tuple[str, str], float]:
    """One run of ``sections`` by ``tree``'s suite with its own environment: each row's Coupler
    figure by (case, reference)."""
    command = [str(tree / ".venv" / "bin" / "python"), "benchmarks/suite.py",
               "--sections", sections, "--out", str(out)]  # fmt: skip
    done = subprocess.run(command, cwd=tree, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"compare: {tree}: the suite failed ({done.returncode}): {done.stderr[-1500:]}")
    rows = json.loads(out.read_text())["rows"]
    return {(r["case"], r["reference"] or ""): float(r["coupler"]) for r in rows}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, required=True, help="the earlier checkout")
    parser.add_argument("--after", type=Path, default=ROOT, help="default: this checkout")
    parser.add_argument("--sections", default="chains,remotes,sockets,participant_side")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    figures: dict[str, dict[tuple[str, str], list[float]]] = {"before": {}, "after": {}}
    with tempfile.TemporaryDirectory(prefix="coupler-compare-") as work:
        for k in range(args.rounds):
            for name, tree in (("before", args.before), ("after", args.after)):
                print(f"round {k + 1}: {name} ({tree})", file=sys.stderr, flush=True)
                got = run_sections(tree.resolve(), args.sections, Path(work) / f"{name}-{k}.json")
                for row, rate in got.items():
                    figures[name].setdefault(row, []).append(rate)
    print("| case | reference | before | after | after / before | spread (before, after) |")
    print("|---|---|---:|---:|---:|---|")
    rows = list(dict.fromkeys([*figures["before"], *figures["after"]]))
    for row in rows:
        before, after = figures["before"].get(row), figures["after"].get(row)
        if not before or not after:
            print(f"| {row[0]} | {row[1]} | {'only after' if after else 'only before'} | | | |")
            continue
        b, a = statistics.median(before), statistics.median(after)
        spread = [f"{(max(v) - min(v)) / statistics.median(v):.0%}" for v in (before, after)]
        print(f"| {row[0]} | {row[1]} | {_figure(b)} | {_figure(a)} | {a / b:.2f} | "
              f"{', '.join(spread)} |")  # fmt: skip
    return 0


def _figure(value: float) -> str:
    return f"{value:,.0f}" if value >= 100 else f"{value:.3g}"


if __name__ == "__main__":
    sys.exit(main())
