"""RunState and Feed in plain Python: which inputs make a reading, and bounded queues."""

from __future__ import annotations

from typing import Any

import pytest

from coupler.channels import RunSetup
from coupler.messages import encode_message
from coupler_railway import Infrastructure
from coupler_railway.messages import BALISE_READING, TRAIN_STATE
from mapserver.__main__ import build_state
from mapserver.config import MapServerSettings
from mapserver.feed import Feed
from mapserver.participant import CHANNELS
from mapserver.state import RunState

from .support import TEST_LINE

DEFAULTS: dict[str, Any] = {c.name: c.start for c in CHANNELS}


@pytest.fixture
def state(test_line: Infrastructure) -> RunState:
    state = build_state(test_line, MapServerSettings(railml=TEST_LINE))
    state.start(RunSetup(run_id="r", start_time=0.0, step_size=1.0), DEFAULTS)
    return state


def ids(state: RunState) -> list[int]:
    return [r.balise_id for r in state.readings]


def test_passed_in_step_keeps_every_balise_of_a_step_in_order(state: RunState) -> None:
    state.step(0.0, 1.0, {"passed_in_step": "301:30:1200.0;302:30:1203.0;303:30:1206.0"})
    state.step(1.0, 1.0, {"passed_in_step": "", "balise_id": 303, "balises_passed": 3})
    state.step(2.0, 1.0, {"passed_in_step": "401:40:1500", "balise_id": 401})
    assert ids(state) == [301, 302, 303, 401]
    assert [r.distance_m for r in state.readings] == [1200.0, 1203.0, 1206.0, 1500.0]
    assert [r.index for r in state.readings] == [0, 1, 2, 3]


def test_balises_passed_count_records_the_last_balise(state: RunState) -> None:
    state.step(0.0, 1.0, {"balise_id": 101, "group_id": 10, "balises_passed": 1})
    state.step(1.0, 1.0, {"balise_id": 101, "group_id": 10, "balises_passed": 1})
    state.step(2.0, 1.0, {"balise_id": 101, "group_id": 10, "balises_passed": 2})  # passed again
    assert ids(state) == [101, 101]
    assert state.readings[0].distance_m == 100.0  # from the railML file


def test_balise_id_changes_are_the_fallback(state: RunState) -> None:
    for t, balise in enumerate([0, 101, 101, 102, 102, 201]):
        state.step(float(t), 1.0, {"balise_id": balise, "group_id": balise // 10})
    assert ids(state) == [101, 102, 201]
    assert [r.time_s for r in state.readings] == [1.0, 3.0, 5.0]


def test_binary_messages(state: RunState) -> None:
    reading = encode_message(
        BALISE_READING,
        {"time_s": 12.5, "balise_id": 201, "group_id": 20, "distance_m": 600.0},
    )
    train = encode_message(
        TRAIN_STATE,
        {"position": {"latitude_deg": 50.001, "longitude_deg": 12.002}, "speed_mps": 7.0},
    )
    state.step(12.0, 1.0, {"balise_reading": reading, "train_state": train})
    state.step(13.0, 1.0, {"balise_reading": reading, "train_state": train})  # same reading
    assert ids(state) == [201] and state.readings[0].time_s == 12.5
    assert state.train is not None and state.train.speed_mps == 7.0
    assert state.train.latitude_deg == 50.001


def test_distance_alone_places_the_train_on_the_line(state: RunState) -> None:
    assert state.train is None  # start values: nowhere yet
    state.step(0.0, 1.0, {"distance": 600.0})
    assert state.train is not None
    assert state.train.latitude_deg == pytest.approx(50.0, abs=1e-3)


def test_subscriber_coalesces_steps_and_resyncs_when_readings_overflow(state: RunState) -> None:
    feed = Feed(state, backlog=4)
    subscriber = feed.subscribe()
    subscriber._resync = False  # as if its snapshot had been sent
    for t in range(10):
        state.step(float(t), 1.0, {"distance": 10.0 * (t + 1)})
    assert subscriber.pending == 1 and subscriber.coalesced == 9
    state.step(10.0, 1.0, {"passed_in_step": "1:1:1;2:1:2;3:1:3"})
    assert subscriber.pending == 4  # 3 readings + latest step
    state.step(11.0, 1.0, {"passed_in_step": "4:1:4;5:1:5"})
    assert subscriber.resyncs == 1 and subscriber.pending == 0
    assert subscriber.peak <= subscriber.backlog + 1


def test_localisation_estimate_interval_and_truth_on_the_line(
    state: RunState, test_line: Infrastructure
) -> None:
    events: list[Any] = []
    state.listeners.append(events.append)
    assert state.snapshot().data["localisation"] is None  # nothing connected
    state.step(0.0, 1.0, {"estimated_front": 0.0, "min_safe_front": 0.0, "max_safe_front": 0.0})
    assert events[-1].data["localisation"] is None  # the interval not connected yet
    state.step(
        1.0,
        1.0,
        {"estimated_front": 500.0, "min_safe_front": 480.0, "max_safe_front": 520.0,
         "true_front": 515.0, "linking_error": True},
    )  # fmt: skip
    shown = events[-1].data["localisation"]
    point = test_line.model.position(500.0)
    assert shown["estimate"] == [point.latitude_deg, point.longitude_deg]
    assert (shown["min_m"], shown["max_m"], shown["true_m"]) == (480.0, 520.0, 515.0)
    assert shown["inside"] is True and shown["linking_error"] is True
    # the interval is the stretch of track between its ends, a point every 5 m
    assert len(shown["interval"]) == 9
    ends = test_line.model.position(480.0), test_line.model.position(520.0)
    assert shown["interval"][0] == [ends[0].latitude_deg, ends[0].longitude_deg]
    assert shown["interval"][-1] == [ends[1].latitude_deg, ends[1].longitude_deg]
    state.step(2.0, 1.0, {"true_front": 530.0})
    assert state.snapshot().data["localisation"]["inside"] is False
