"""What the railway package's tests share besides fixtures (those are in conftest.py): balise
detections as Perception sends them, and the table of them test_scoring.py and
test_run_report.py play.

Ground truth: balises 1 (100 m) and 2 (103 m) passed at 10 s, balise 3 (600 m) at 50 s.
"""

from __future__ import annotations

from coupler.messages import encode_message
from coupler_railway.messages import BALISE_DETECTIONS


def detections(time_s: float, *positions: float, ahead: float = 20.0) -> bytes:
    return encode_message(
        BALISE_DETECTIONS,
        {
            "time_s": time_s,
            "sensor": "front",
            "detections": [
                {"time_s": time_s, "track_position_m": p, "distance_ahead_m": ahead,
                 "confidence": 0.9}
                for p in positions
            ],
        },
    )  # fmt: skip


ROWS = [
    (0.0, detections(0.0), ""),
    (5.0, detections(5.0, 100.4, 102.7), ""),  # both of the group, 0.4 and 0.3 m off
    (6.0, detections(6.0, 100.1), ""),
    (10.0, detections(10.0), "1:1:100;2:1:103"),
    (20.0, detections(20.0, 350.0), ""),  # nothing there: false
    (50.0, detections(50.0), "3:2:600"),  # never seen: missed
    (55.0, detections(55.0, 600.2), ""),  # after it was passed: false
]
