"""FMUs as participants (the ``fmu`` extra: FMPy, numpy).

- ``participant``: ``FmuParticipant``, an FMU run in-process through FMPy;
- ``calls``: the FMI calls prepared once per instance that a step makes;
- ``channels``: which variables are channels, and which FMUs are refused;
- ``host``: an FMU in a child process of its own (``python -m coupler.fmu.host``), reached over
  a unix socket.
"""

from coupler.fmu.participant import FmuParticipant

__all__ = ["FmuParticipant"]
