"""The mock keeps frames of the current state only, and no more than its byte bound of them;
one frame renders at a time, so requests for the same frame share one render.

    sensors (30 of them) --> Cameras(renderer) --frame(name, shot)--> bytes, labels

Before the bound, every sensor's last frame stayed cached forever (30 sensors' frames took the
mock's memory to 1 GB) and six concurrent GETs of one uncached 4K depth frame rendered it six
times at once (4.7 GB).
"""

from __future__ import annotations

import threading

from openrails_mock.renderer import Renderer, View
from openrails_mock.route import StraightRoute
from openrails_mock.scene import Scene
from openrails_mock.sensors import Cameras, SensorSpec, Shot

FRAME = 64 * 48 * 3


def cameras(count: int, **bounds: int) -> Cameras:
    specs = [
        SensorSpec(name=f"cam{i}", type="rgb", train_name="PLAYER", width=64, height=48,
                   fov_deg=45.0)
        for i in range(count)
    ]  # fmt: skip
    return Cameras(specs, Renderer(Scene(StraightRoute(length_m=500.0))), **bounds)  # type: ignore[arg-type]


def test_a_new_step_drops_the_last_steps_frames() -> None:
    sensors = cameras(30)
    here, there = Shot(50.0, View()), Shot(51.0, View())
    for name in sensors.specs:
        sensors.frame(name, here)
    assert sensors.cached_bytes == 30 * FRAME
    sensors.frame("cam0", there)
    assert sensors.cached_bytes == FRAME  # only the current state's
    assert sensors.cached("cam1", here) is None


def test_the_cache_holds_at_most_its_bound() -> None:
    sensors = cameras(5, max_cached_bytes=2 * FRAME + 10)
    shot = Shot(50.0, View())
    frames = [sensors.frame(name, shot).data for name in sensors.specs]
    assert sensors.cached_bytes <= 2 * FRAME + 10
    again = [sensors.frame(name, shot).data for name in sensors.specs]  # rendered anew
    assert again == frames  # the same state, the same bytes


def test_concurrent_requests_for_one_frame_render_it_once() -> None:
    sensors = cameras(1)
    shot = Shot(50.0, View())
    results: list[bytes] = []
    threads = [
        threading.Thread(target=lambda: results.append(sensors.frame("cam0", shot).data))
        for _ in range(6)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert sensors.renders == 1
    assert len(set(results)) == 1 and len(results) == 6
