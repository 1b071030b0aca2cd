"""Browser files copied out of an npm package's folder into a service's static folder."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from coupler_tools import vendor


def _dist(root: Path) -> Path:
    """A package's dist folder as npm installs it: a script, a style sheet, an image folder."""
    dist = root / "node_modules" / "leaflet" / "dist"
    (dist / "images").mkdir(parents=True)
    (dist / "leaflet.js").write_text("/* js */")
    (dist / "leaflet.css").write_text("/* css */")
    (dist / "images" / "marker.png").write_bytes(b"\x89PNG")
    (dist / "unused.map").write_text("{}")
    return dist


NAMES = ["leaflet.js", "leaflet.css", "images"]


def test_copy_takes_the_named_files_and_folders(tmp_path: Path) -> None:
    target = tmp_path / "static" / "vendor" / "leaflet"
    assert vendor.missing(target, NAMES) == NAMES
    assert vendor.copy(_dist(tmp_path), NAMES, target) == target
    assert vendor.missing(target, NAMES) == []
    assert (target / "images" / "marker.png").read_bytes() == b"\x89PNG"
    assert not (target / "unused.map").exists()
    # again over what is there (make assets run twice)
    vendor.copy(_dist(tmp_path / "again"), NAMES, target)
    assert sorted(p.name for p in target.iterdir()) == sorted(NAMES)


def test_copy_names_what_npm_has_not_installed(tmp_path: Path) -> None:
    dist = _dist(tmp_path)
    (dist / "leaflet.css").unlink()
    with pytest.raises(FileNotFoundError, match=r"lacks leaflet\.css: run `npm ci` first"):
        vendor.copy(dist, NAMES, tmp_path / "vendor")
    assert not (tmp_path / "vendor").exists()


def test_command_says_what_was_copied_or_why_not(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "vendor"

    def copy_from(node_modules: Path) -> Path:
        return vendor.copy(node_modules / "leaflet" / "dist", NAMES, target)

    _dist(tmp_path)
    node_modules = tmp_path / "node_modules"
    assert vendor.command("python -m x.assets", "Leaflet", copy_from, node_modules, []) == 0
    assert capsys.readouterr().out == f"Leaflet copied to {target}\n"
    elsewhere = ["--node-modules", "/nowhere"]
    assert vendor.command("python -m x.assets", "Leaflet", copy_from, tmp_path, elsewhere) == 1
    said = capsys.readouterr()
    assert not said.out
    assert re.fullmatch(r"python -m x\.assets: .* run `npm ci` first\n", said.err)
