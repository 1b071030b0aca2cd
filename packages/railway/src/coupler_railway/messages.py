"""The railway's structured values (``railway.proto``), registered with Coupler's message registry.

Importing this module makes ``coupler.v1.TrainState``, ``coupler.v1.BaliseReading`` and
``coupler.v1.GeoPoint`` known to ``coupler.messages``: binary channels carrying them can be
encoded, decoded and written as JSON in results. The message names live here and nowhere else.
"""

from __future__ import annotations

from coupler.messages import register
from coupler.v1.railway_pb2 import BaliseReading, GeoPoint, TrainState

register(TrainState, BaliseReading, GeoPoint)

TRAIN_STATE = TrainState.DESCRIPTOR.full_name
"""Full name of the train state message (``coupler.v1.TrainState``)."""
BALISE_READING = BaliseReading.DESCRIPTOR.full_name
"""Full name of the balise reading message."""
GEO_POINT = GeoPoint.DESCRIPTOR.full_name
"""Full name of the WGS84 point message."""
