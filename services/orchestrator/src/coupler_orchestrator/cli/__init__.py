"""The ``coupler`` command line."""
