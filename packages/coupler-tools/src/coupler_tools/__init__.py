"""Coupler's build helpers, which the products use at set-up and at run time but a participant
author never needs (so they are not in the participant SDK, ``coupler``):

- ``coupler_tools.fmubuild``: FMUs compiled from C sources with FMPy's FMI headers (the ``fmu``
  extra), and FMU archives written whole or not at all; ``python -m coupler_tools.fmubuild
  SRC_ROOT OUT_DIR`` (``make fmus``). The TrackBalises service builds its FMU with it at start,
  ``coupler export-fmu`` writes its archive with it.
- ``coupler_tools.vendor``: browser files copied out of ``node_modules`` into a service's
  static folder (``make assets``), and the check a page's server makes that they are there.

The public API is these two modules (``__all__``), each declaring its own names;
``tests/test_exported_members.py`` keeps all three. Nothing in ``coupler`` imports this package.
"""

__all__ = ["fmubuild", "vendor"]
