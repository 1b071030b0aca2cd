"""Soak: a long run with three remote participants; errors and every process's memory over time.

    Gain1 --y--> Gain2.u --y--> Gain3.u        (three `python -m coupler.examples gain`)

    .venv/bin/python benchmarks/soak.py              # 1e6 steps (about 15-25 minutes here)
    .venv/bin/python benchmarks/soak.py --steps 20000

The orchestrator runs as its own process (`coupler run`, Jacobi, h = 1 ms, results every 1000
steps so the disk is not the subject). The resident set size (VmRSS) of the orchestrator and of
each participant is sampled every few seconds against the steps done (summary.json's progress),
and the growth from the first sample past 1e4 steps to the end is printed per process: memory
must stay flat. Prints PASS/FAIL for "no error" and "RSS within 5 % (or 3 MB) of its 1e4-step
value" and exits 1 on a failure.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from coupler.testing import free_port

SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription version="1.0" name="Soak"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription">
  <ssd:System name="Soak">
    <ssd:Elements>
{components}
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="Gain1" startConnector="y" endElement="Gain2" endConnector="u"/>
      <ssd:Connection startElement="Gain2" startConnector="y" endElement="Gain3" endConnector="u"/>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="{stop}"/>
</ssd:SystemStructureDescription>
"""
COMPONENT = """      <ssd:Component name="Gain{i}" type="application/x-coupler-grpc"
                     source="grpc://127.0.0.1:{port}">
        <ssd:Connectors>
          <ssd:Connector name="u" kind="input"/><ssd:Connector name="y" kind="output"/>
        </ssd:Connectors>
      </ssd:Component>"""
STEP = 0.001


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def steps_done(summary: Path) -> int:
    try:
        return int(json.loads(summary.read_text())["steps"])
    except (OSError, ValueError, KeyError):
        return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--every", type=float, default=5.0, help="sampling interval [s]")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="coupler-soak-"))
    ports = [free_port() for _ in range(3)]
    logs = [(work / f"gain{i + 1}.log").open("wb") for i in range(3)]
    gains = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "coupler.examples",
                "gain",
                "--port",
                str(port),
                "--log-level",
                "WARNING",
            ],
            stdout=subprocess.DEVNULL,
            stderr=log,
        )
        for port, log in zip(ports, logs, strict=True)
    ]
    ssd = work / "soak.ssd"
    components = "\n".join(COMPONENT.format(i=i + 1, port=p) for i, p in enumerate(ports))
    ssd.write_text(SSD.format(components=components, stop=args.steps * STEP))
    out = work / "out"
    print(f"soak: {args.steps} steps, 3 remote participants, work in {work}", flush=True)
    time.sleep(1.5)
    started = time.monotonic()
    orchestrator = subprocess.Popen(
        [sys.executable, "-m", "coupler_orchestrator", "run", str(ssd), "--out", str(out),
         "--step", str(STEP), "--output-interval", str(1000 * STEP), "--no-progress"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    names = ["orchestrator", "Gain1", "Gain2", "Gain3"]
    pids = [orchestrator.pid, *(g.pid for g in gains)]
    samples: list[tuple[int, list[float | None]]] = []
    print(f"{'steps':>9} {'wall s':>7} " + " ".join(f"{n + ' MB':>15}" for n in names))
    while orchestrator.poll() is None:
        time.sleep(args.every)
        sample = (steps_done(out / "summary.json"), [rss_mb(pid) for pid in pids])
        samples.append(sample)
        cells = " ".join(f"{v:>15.1f}" if v is not None else f"{'-':>15}" for v in sample[1])
        print(f"{sample[0]:>9} {time.monotonic() - started:>7.0f} {cells}", flush=True)
    stdout, stderr = orchestrator.communicate()
    wall = time.monotonic() - started
    for gain in gains:
        gain.terminate()
        gain.wait(10)
    for log in logs:
        log.close()
    summary = json.loads((out / "summary.json").read_text())
    participant_errors = [
        line
        for i in range(3)
        for line in (work / f"gain{i + 1}.log").read_text().splitlines()
        if '"level": "error"' in line
    ]
    print(f"\nrun: {summary['status']} {summary['steps']} steps in {wall:.0f} s "
          f"({summary['steps'] / wall:.0f} steps/s); participant errors: "
          f"{len(participant_errors)}")  # fmt: skip
    ok = summary["status"] == "completed" and summary["steps"] == args.steps
    ok = ok and not participant_errors
    print(f"{'PASS' if ok else 'FAIL'}  no error (status, steps, participants' logs)")
    baseline = next((s for s in samples if s[0] >= 10_000), None)
    last = samples[-2] if len(samples) > 1 else None  # the final sample may see exits
    if baseline is None or last is None:
        print("SKIP  memory: the run was too short to sample past 1e4 steps")
        return 0 if ok else 1
    print(f"\nRSS from {baseline[0]} to {last[0]} steps:")
    for name, before, after in zip(names, baseline[1], last[1], strict=True):
        if before is None or after is None:
            continue
        grown = after - before
        flat = grown <= max(0.05 * before, 3.0)
        ok = ok and flat
        print(f"{'PASS' if flat else 'FAIL'}  {name:<13} {before:7.1f} -> {after:7.1f} MB "
              f"({grown:+.1f} MB, {grown / before:+.1%})")  # fmt: skip
    if stderr.strip():
        print("\norchestrator stderr (last lines):\n" + "\n".join(stderr.splitlines()[-5:]))
    del stdout
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
