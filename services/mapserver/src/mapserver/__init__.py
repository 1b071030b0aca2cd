"""mapserver."""
