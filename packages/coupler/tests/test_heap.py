"""coupler.heap: a process that frees megabyte buffers at every step keeps them for the next.

a child process: five 1 MiB buffers made and freed, 50 times --> its minor page faults,
with and without keep_freed_memory()
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

STEPS = """
import resource, sys
from coupler.heap import keep_freed_memory
kept = keep_freed_memory() if sys.argv[1] == "kept" else False
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(50):
    frames = [bytearray(1 << 20) for _ in range(5)]
    del frames
print(kept, (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 50)
"""


def faults(how: str, **env: str) -> tuple[bool, float]:
    environment = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    done = subprocess.run([sys.executable, "-c", STEPS, how], capture_output=True, text=True,
                          check=True, env={**environment, **env})  # fmt: skip
    kept, per_step = done.stdout.split()
    return kept == "True", float(per_step)


@pytest.mark.skipif(sys.platform != "linux", reason="glibc's malloc: Linux only")
def test_freed_frames_are_kept_for_the_next_step() -> None:
    kept, with_it = faults("kept")
    assert kept
    _, without = faults("plain")
    assert without > 600  # every page of the five buffers faulted in again at each step
    assert with_it < without / 10


def test_the_users_own_setting_wins() -> None:
    kept, _ = faults("kept", MALLOC_TRIM_THRESHOLD_="1048576")
    assert not kept
