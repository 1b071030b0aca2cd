"""Coupler's development tools, apart from what users install: ``coupler_dev.devcerts`` (a
throwaway certificate authority for tests and local fleets: ``python -m coupler_dev.devcerts``).
Nothing in ``coupler`` or ``coupler_orchestrator`` imports this package."""
