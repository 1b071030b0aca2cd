"""The ``coupler`` command line: ``main`` (the entry point), ``parser`` (the commands, one module
each, importing what they need only when they run), ``session`` (what a command has seen, for
its last words), ``interrupts`` (Ctrl-C, SIGTERM and a thread stuck in C), ``exits`` (codes)."""

from coupler_orchestrator.cli.main import main

__all__ = ["main"]
