"""The cffi API-mode module of csrc/step_streams.h (compiled; see coupler_native)."""

from typing import Any

ffi: Any
lib: Any
