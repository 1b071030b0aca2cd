"""The benchmark suite's sections, one module each (``suite.py`` runs them in turn); ``common``
holds what they share, ``raw`` the bare gRPC floors, ``peers`` FMPy, libcosim and mosaik."""
