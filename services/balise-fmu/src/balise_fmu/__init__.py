"""balise_fmu: a generic FMU host participant, and the TrackBalises FMU it serves by default.

- ``python -m balise_fmu``: serve any co-simulation FMU over Coupler's gRPC protocol
  (``coupler.fmu.FmuParticipant`` behind ``coupler.server.serve``).
- ``python -m balise_fmu.build``: build TrackBalises.fmu from a railML file (C model in
  ``services/balise-fmu/fmu``, resources written by ``coupler_railway``).
"""
