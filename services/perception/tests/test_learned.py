"""The learned detector: its model file (``make detector-model``, build/models/balise-pixels.json,
trained on the Annaberg-Schwarzenberg line) on frames of the railway package's test line, which
it never saw; the participant's ``detector`` parameter; model files that cannot be used.

    mock renderer (test line, fog) --rgb--> PixelModel.mask --> find() --> distance ahead
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from coupler.channels import RunSetup
from coupler.client import RemoteParticipant
from coupler.errors import ParticipantError
from coupler.server import ParticipantServer
from coupler_railway import Infrastructure
from openrails_mock.conditions import Conditions
from openrails_mock.renderer import Renderer, View
from openrails_mock.scene import Scene
from perception.detector import Mounting, find
from perception.learned import ModelError, PixelModel
from perception.participant import MODEL, PerceptionParticipant

from .support import CAMERA, ROOT, frame, intrinsics, state

BUILT = ROOT / MODEL


@pytest.fixture(scope="module")
def model() -> PixelModel:
    return PixelModel.load(BUILT)


def test_in_fog_the_learned_mask_finds_the_balises_the_colour_thresholds_lose(
    model: PixelModel, test_line: Infrastructure
) -> None:
    """25 m visibility: a balise 15 m ahead keeps 9 % of its contrast; the colour thresholds
    see nothing of it, the learned mask both balises of the group, within 1 m."""
    foggy = Renderer(Scene.of_infrastructure(test_line),
                     conditions=Conditions(light="sun", visibility_m=25.0))  # fmt: skip
    first = next(b for b in test_line.balises if b.code == 101).distance_m
    front = first - 15.0
    pixels = foggy.render(CAMERA, front, View(elapsed_s=1.0, clock_s=12 * 3600.0)).pixels
    assert find(pixels, intrinsics(), Mounting()).detections == []
    found = find(pixels, intrinsics(), Mounting(), mask=model.mask, max_width_ratio=2.0)
    truth = sorted(b.distance_m - front for b in test_line.balises if b.code in (101, 102))
    assert [d.distance_ahead_m for d in found.detections] == pytest.approx(truth, abs=1.0)


def test_a_model_file_records_its_training_and_validation(model: PixelModel) -> None:
    trained = model.trained or {}
    assert trained["frames"]["train"] > 0 and trained["frames"]["validation"] > 0
    learned, colour = trained["validation"]["learned"], trained["validation"]["colour"]
    assert learned["balises"] == colour["balises"] > 0


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "does not exist: make detector-model writes it"),
        ("{", "cannot be read"),
        ('{"features": ["r"]}', "was trained on features ['r']"),
    ],
)
def test_model_files_that_cannot_be_used_are_refused_naming_them(
    tmp_path: Path, content: str | None, message: str
) -> None:
    path = tmp_path / "model.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(ModelError, match=re.escape(message)) as caught:
        PixelModel.load(path)
    assert str(path) in str(caught.value)


def test_a_tree_whose_nodes_point_outside_it_is_refused(tmp_path: Path) -> None:
    data = json.loads(BUILT.read_text())
    data["nodes"]["left"][0] = 10**6
    path = tmp_path / "model.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ModelError, match="its nodes are not a tree"):
        PixelModel.load(path)


@pytest.mark.parametrize(
    ("detector", "model", "message"),
    [
        ("neural", BUILT, "parameter 'detector' is 'neural'; give one of colour, learned"),
        ("learned", Path("/nonexistent/model.json"), "does not exist: make detector-model"),
    ],
)
async def test_the_participant_refuses_an_unknown_detector_or_a_missing_model(
    detector: str, model: Path, message: str
) -> None:
    server = ParticipantServer(PerceptionParticipant(model=model), port=0)
    await server.start()
    try:
        async with RemoteParticipant(server.address, name="Perception") as remote:
            with pytest.raises(ParticipantError, match=re.escape(message)):
                await remote.initialize(
                    RunSetup(
                        run_id="p", start_time=0.0, step_size=0.2, parameters={"detector": detector}
                    )
                )
    finally:
        await server.stop(grace=0.1)


async def test_the_participant_runs_the_learned_detector(
    renderer: Renderer, test_line: Infrastructure
) -> None:
    server = ParticipantServer(PerceptionParticipant(model=BUILT), port=0)
    await server.start()
    try:
        async with RemoteParticipant(server.address, name="Perception") as remote:
            await remote.initialize(
                RunSetup(
                    run_id="p", start_time=0.0, step_size=0.2, parameters={"detector": "learned"}
                )
            )
            first = next(b for b in test_line.balises if b.code == 101).distance_m
            out = await remote.do_step(
                1.0, 0.2, {"image": frame(renderer, first - 20.0), "train_state": state(0.0)}
            )
            await remote.terminate()
    finally:
        await server.stop(grace=0.1)
    assert out["detection_count"] == 2  # in clear air as the colour detector (101 and 102)


@pytest.mark.parametrize(
    ("light", "clock_h"),
    [
        (Conditions(light="sun"), 12.0),
        (Conditions(light="sun"), 23.0),
        (Conditions(light="sun", visibility_m=25.0), 23.0),
        (Conditions(light="sun", season="winter", weather="snow", snow_cover=0.8, dirt=0.8), 8.5),
    ],
    ids=["noon", "night", "fog-at-night", "snow-and-dirt"],
)
def test_the_compiled_pass_gives_numpys_probabilities_bit_for_bit(
    model: PixelModel, test_line: Infrastructure, light: Conditions, clock_h: float
) -> None:
    """``probability`` (one compiled pass, ``perception.pixels``) against
    ``probability_numpy`` (the step-by-step numpy the model was trained with) on frames of
    the test line, on an odd-width crop of them (the median of an odd row) and on noise."""
    renderer = Renderer(Scene.of_infrastructure(test_line), conditions=light)
    first = next(b for b in test_line.balises if b.code == 101).distance_m
    frames = [
        renderer.render(CAMERA, first - ahead, View(elapsed_s=1.0, clock_s=clock_h * 3600.0)).pixels
        for ahead in (6.0, 20.0)
    ]
    frames.append(frames[0][:, 1:])  # 799 columns
    frames.append(np.random.default_rng(7).integers(0, 256, (60, 81, 3), dtype=np.uint8))
    for pixels in frames:
        expected = model.probability_numpy(pixels)
        assert (expected > 0).any()  # candidates were judged
        assert np.array_equal(model.probability(pixels), expected)


WARMED_THEN_A_FRAME = """
import sys
from pathlib import Path
import numpy as np
from perception import pixels
from perception.learned import PixelModel
pixels.warm()
compiled = list(pixels.probability.signatures)
PixelModel.load(Path(sys.argv[1])).probability(np.zeros((600, 800, 3), dtype=np.uint8))
added = [s for s in pixels.probability.signatures if s not in compiled]
print(f"warmed {len(compiled)}, added by the frame {len(added)}: {added}")
sys.exit(1 if added or not compiled else 0)
"""


def test_warming_compiles_the_kernel_a_frame_uses() -> None:
    """The participant warms the compiled pass at Initialize (``pixels.warm``): a frame after
    it needs no other compilation, so no step pays for one. In a fresh interpreter, as the
    participant's process starts (here every frame before has compiled it already)."""
    done = subprocess.run(
        [sys.executable, "-c", WARMED_THEN_A_FRAME, str(BUILT)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stdout + done.stderr
