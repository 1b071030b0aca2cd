"""A picture of a page in Debian's Chromium (Playwright, as the project's browser tests start
it: coupler_dev.browser), for the docs: the envelope's HTML, the map, the monitor.

    .venv/bin/python scripts/screenshot.py results/campaigns/perception-campaign/envelope.html \\
        docs/img/perception-envelope.png [--width 1000] [--height 1400]

A file path is opened as file://; the picture is the page's top ``--height`` pixels (the whole
page with --height 0), written as an 8-bit palette PNG to stay small.
"""

from __future__ import annotations

import argparse
import asyncio
import io
from pathlib import Path

from PIL import Image

from coupler_dev.browser import chromium


async def shoot(url: str, out: Path, width: int, height: int) -> None:
    async with chromium() as browser:
        page = await browser.new_page(viewport={"width": width, "height": max(height, 400)})
        await page.goto(url)
        await page.wait_for_load_state("load")
        picture = await page.screenshot(full_page=height == 0)
    image = Image.open(io.BytesIO(picture)).convert("RGB")
    image.quantize(colors=128, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("page", help="a file or an http(s) URL")
    parser.add_argument("out", type=Path)
    parser.add_argument("--width", type=int, default=1000)
    parser.add_argument("--height", type=int, default=1400)
    args = parser.parse_args()
    page = str(args.page)
    url = page if page.startswith(("http://", "https://")) else Path(page).resolve().as_uri()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    asyncio.run(shoot(url, args.out, args.width, args.height))
    print(f"{args.out}: {args.out.stat().st_size // 1024} kB")


if __name__ == "__main__":
    main()
