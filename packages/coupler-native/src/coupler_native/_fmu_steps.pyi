"""The cffi API-mode module of csrc/fmu_steps.h (compiled; see coupler_native)."""

from typing import Any

ffi: Any
lib: Any
