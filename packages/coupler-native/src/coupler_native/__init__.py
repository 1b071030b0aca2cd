"""Coupler's native code, compiled when this wheel was built (nothing compiles at run time):

Every module is a CPython extension of the stable ABI (one binding technology):

- ``coupler_native._fmu_steps``: the in-process FMUs' step loop in C (``csrc/fmu_steps.c``,
  declared by ``csrc/fmu_steps.h``; its Python face ``csrc/fmu_steps_module.c``);
- ``coupler_native._step_streams``: remote members' StepStream over C++ gRPC
  (``csrc/step_streams.cc``, declared by ``csrc/step_streams.h``; its Python face
  ``csrc/step_streams_module.c``);
- ``coupler_native._rows``: results.csv's lines made in one pass, the native FMU step's rows
  read from its arrays and its row log, step latencies counted (``csrc/rows.c``);
- ``coupler_native._answers``: a remote member's step answer read from its bytes
  (``csrc/answers.c``);
- ``PROXY``: the folder of the proxy FMU's binaries (``CouplerProxy.so``, FMI 2 and 3, its
  gRPC client library and every library they load), which ``coupler export-fmu`` copies
  into each FMU's ``binaries/<platform>/``.

The orchestrator imports the modules when it steps (``native_fmu_step`` and
``native_step_channel`` in ``coupler_orchestrator.master``) and records
(``coupler_orchestrator.outputs.csv``); nothing here is loaded from outside the installed
package.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["PROXY", "PROXY_BINARY"]

PROXY = Path(__file__).parent / "proxy"
"""The proxy FMU's binaries, copied whole into an exported FMU."""
PROXY_BINARY = "CouplerProxy.so"
"""The file of ``PROXY`` that is the FMU's binary (its model identifier is ``CouplerProxy``)."""
