"""Stage 7: the master algorithm (``loop``), the watchdog over calls on its thread, and the
native step paths (the native FMU step, the native step channel)."""
