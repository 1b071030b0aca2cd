"""The generated code in coupler/v1 is what `make proto` produces from proto/ today."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
PATH = os.environ.get("PATH", "")
GENERATED = ROOT / "packages" / "coupler" / "src" / "coupler" / "v1"


def test_generated_code_is_fresh(tmp_path: Path) -> None:
    protos = sorted(str(p.relative_to(ROOT / "proto")) for p in (ROOT / "proto").rglob("*.proto"))
    subprocess.run(
        [
            sys.executable,
            "-m",
            "grpc_tools.protoc",
            "-Iproto",
            f"--python_out={tmp_path}",
            f"--grpc_python_out={tmp_path}",
            f"--mypy_out={tmp_path}",
            f"--mypy_grpc_out={tmp_path}",
            *protos,
        ],
        cwd=ROOT,
        check=True,
        capture_output=True,
        # the protoc-gen-mypy plugins beside this interpreter, also when the venv is not active
        env={**os.environ, "PATH": os.pathsep.join([str(Path(sys.executable).parent), PATH])},
    )
    fresh = {p.name: p.read_bytes() for p in (tmp_path / "coupler" / "v1").iterdir()}
    committed = {p.name: p.read_bytes() for p in GENERATED.iterdir() if p.name in fresh}
    stale = sorted(name for name in fresh if committed.get(name) != fresh[name])
    assert not stale, f"generated protobuf code is stale ({', '.join(stale)}): run 'make proto'"
