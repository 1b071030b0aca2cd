"""``coupler plot`` on the results of real runs: a PNG opened and looked at, an HTML page that
needs nothing but itself, rendered in Debian's Chromium.

    coupler run chain.ssd (0..2 s) ---> long/  \\
    coupler run chain.ssd (0..1 s) ---> short/ -+-> coupler plot long short Integ.x 'Source.*'
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import pytest
from PIL import Image

from coupler_dev.browser import CHROMIUM, NO_CHROMIUM, chromium
from coupler_orchestrator.assets import VENDOR

from ..support import DATA, REPO, Coupler

ARTIFACT = REPO / "test-artifacts" / "plot.png"


@pytest.fixture
def runs(coupler: Coupler, fmus: dict[str, Path], tmp_path: Path) -> tuple[Path, Path]:
    long, short = tmp_path / "long", tmp_path / "short"
    assert coupler("run", DATA / "chain.ssd", "--out", long).code == 0
    assert coupler("run", DATA / "chain.ssd", "--out", short, "--stop-time", "1").code == 0
    return long, short


def test_png_of_two_runs(coupler: Coupler, runs: tuple[Path, Path], tmp_path: Path) -> None:
    long, short = runs
    out = tmp_path / "plot.png"
    outcome = coupler("plot", long, short / "results.csv", "Integ.x", "Source.*", "-o", out)
    assert outcome.code == 0, outcome.err
    assert outcome.out == f"plot: {out}\n"
    with Image.open(out) as image:
        assert image.format == "PNG"
        width, height = image.size
        assert width >= 800 and height >= 500  # two charts: [m] and (no unit)
        pixels = image.convert("RGB")
        colours = pixels.getcolors(maxcolors=1 << 20)
    assert colours is not None
    white = sum(n for n, c in colours if c == (255, 255, 255))
    assert white < 0.97 * width * height, "the picture is (almost) blank"

    def near(target: tuple[int, int, int]) -> int:
        return sum(
            n for n, c in colours if sum(abs(a - b) for a, b in zip(c, target, strict=True)) < 60
        )

    # the first two series' palette colours are drawn (lines, not just their legend swatches)
    assert near((0x1F, 0x77, 0xB4)) > 300
    assert near((0xD6, 0x27, 0x28)) > 300


def test_html_is_self_contained(coupler: Coupler, runs: tuple[Path, Path], tmp_path: Path) -> None:
    long, short = runs
    out = tmp_path / "plot.html"
    outcome = coupler("plot", long, short, "Integ.x", "Feed.*", "-o", out, "--title", "chain")
    assert outcome.code == 0, outcome.err
    page = out.read_text()
    assert re.findall(r"""(?:src|href)\s*=\s*["'](?!data:)""", page) == []
    assert "http://" not in page and "https://" not in page.replace("https://github", "")
    assert (VENDOR / "uPlot.iife.min.js").read_text()[:200] in page  # the library, inlined
    assert '"label": "long: Integ.x"' in page and '"label": "short: Feed.real_out"' in page
    assert '"axis": "[m]"' in page and '"axis": "(no unit)"' in page


@pytest.mark.skipif(not CHROMIUM.exists(), reason=NO_CHROMIUM)
async def test_html_renders_in_chromium(runs: tuple[Path, Path], tmp_path: Path) -> None:
    from coupler_orchestrator.tools.plot import plot

    out = plot(list(runs), ["Integ.x", "Source.*"], tmp_path / "plot.html", title="chain")
    async with chromium() as browser:
        page = await browser.new_page(viewport={"width": 1100, "height": 800})
        errors: list[str] = []
        requests: list[str] = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("request", lambda r: requests.append(r.url))
        await page.goto(out.as_uri())
        await page.wait_for_function("window.couplerPlot && window.couplerPlot.ready")
        charts: list[dict[str, Any]] = await page.evaluate(
            """() => window.couplerPlot.charts.map((chart) => {
                const canvas = chart.root.querySelector("canvas");
                const pixels = canvas.getContext("2d")
                    .getImageData(0, 0, canvas.width, canvas.height).data;
                let drawn = 0;
                for (let i = 3; i < pixels.length; i += 4) if (pixels[i] > 0) drawn++;
                return {series: chart.series.length, drawn, labels:
                    chart.series.map((s) => s.label)};
            })"""
        )
        # by unit, in the order of the CSV's columns: Source.* (no unit), then Integ.x [m];
        # each with the time series and one series per run and channel
        assert [c["series"] for c in charts] == [7, 3]
        assert charts[1]["labels"][1:] == ["long: Integ.x", "short: Integ.x"]
        assert all(c["drawn"] > 1000 for c in charts), charts
        assert errors == []
        assert all(u.startswith(("file://", "data:")) for u in requests), requests
        ARTIFACT.parent.mkdir(parents=True, exist_ok=True)
        await page.screenshot(path=str(ARTIFACT), full_page=True)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["Nope.*"],
            "no channel matches 'Nope.*'; the results have: Feed.binary_out, Feed.bool_out",
        ),
        (["-o", "x.svg"], "write FILE.png (a picture) or FILE.html (interactive)"),
        (["no/such/run"], "no/such/run: no such results directory or results.csv"),
    ],
)
def test_bad_requests_are_named(
    coupler: Coupler, runs: tuple[Path, Path], tmp_path: Path, args: list[str], message: str
) -> None:
    output = ["-o", str(tmp_path / "p.png")] if "-o" not in args else []
    outcome = coupler("plot", runs[0], *args, *output)
    assert outcome.code == 1
    assert message in outcome.err
    assert "Traceback" not in outcome.err


def test_a_campaigns_runs_are_labelled_by_their_parameters(
    coupler: Coupler, runs: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Runs as a campaign leaves them (out/runs/<n>-<key>/ with variant.json): each series is
    named by the parameters that differ, the title is the campaign's folder, not every path."""
    campaign = tmp_path / "campaign"
    variants = [
        {"Gain.gain": 2.0, "Source.slope": 0.5},
        {"Gain.gain": 3.0, "Source.slope": 0.5},
    ]
    folders = []
    for index, (run, variant) in enumerate(zip(runs, variants, strict=True), start=1):
        folder = campaign / "runs" / f"{index:03d}-{index:012x}"
        shutil.copytree(run, folder)
        (folder / "variant.json").write_text(json.dumps(variant))
        folders.append(folder)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "plot.html"
    outcome = coupler("plot", *folders, "Integ.x", "-o", out)
    assert outcome.code == 0, outcome.err
    data = json.loads(re.search(r'id="plot-data"[^>]*>(.*?)</script>', out.read_text()).group(1))
    assert [s["label"] for s in data["charts"][0]["series"]] == [
        "Gain.gain=2: Integ.x",
        "Gain.gain=3: Integ.x",
    ]  # Source.slope is the same in both: not repeated
    assert data["title"] == "campaign: 2 runs over Gain.gain"
