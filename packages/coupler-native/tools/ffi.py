"""Writes the C source of a cffi API-mode extension module whose declarations are one header.

    python tools/ffi.py MODULE HEADER OUT.c

The header is the only place its structs and functions are declared: cffi reads it as the
module's cdef, and the generated source includes it, so the compiler checks that the
binding's layout is the C code's. (CMakeLists.txt runs this at build time.)
"""

from __future__ import annotations

import sys
from pathlib import Path

import cffi


def main(module: str, header: Path, out: Path) -> None:
    ffi = cffi.FFI()
    ffi.cdef(header.read_text(encoding="utf-8"))
    ffi.set_source(module, f'#include <stdbool.h>\n#include <stddef.h>\n#include "{header.name}"\n')
    ffi.emit_c_code(str(out))


if __name__ == "__main__":
    main(sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]))
