"""coupler_orchestrator."""
