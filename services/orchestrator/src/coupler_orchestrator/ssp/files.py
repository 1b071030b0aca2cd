"""The files of a scenario: where a source attribute points, and reading what it points to."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import unquote, urlsplit

from coupler.errors import ScenarioError

from .documents import Element, parse, validate, where
from .tool_annotations import unsupported


class Documents:
    """The files of one scenario: the SSD and what it references (.ssv, .ssm, .ssb, FMUs).

    Sources are URIs relative to the SSD; inside an .ssp (``confined``) they may not point out
    of the archive. Warnings about what a referenced file holds but the loader does not apply
    go to ``warnings``.
    """

    def __init__(self, resource_dir: Path, *, confined: bool, warnings: list[str]) -> None:
        self.resource_dir = resource_dir
        self.confined = confined
        self.warnings = warnings

    def resolve(
        self, source: str, element: Element, display: str, *, what: str, shown: str = ""
    ) -> Path:
        """An SSD-relative URI as an absolute path, confined to the archive for .ssp files.
        ``shown``: the source as a message quotes it (as written, when it expanded ``${VAR}``s
        whose values a message never shows)."""
        shown = shown or f"'{source}'"
        parts = urlsplit(source)
        if parts.scheme and parts.scheme != "file" and len(parts.scheme) > 1:
            scheme = f"the scheme '{parts.scheme}:'" if shown == f"'{source}'" else "a scheme"
            raise ScenarioError(
                f"{where(display, element)}: {what} source {shown} uses {scheme}, which is not "
                "supported; use a path relative to the SSD"
            )
        raw = unquote(parts.path if parts.scheme == "file" else source)
        path = (self.resource_dir / raw).resolve()
        if self.confined and not path.is_relative_to(self.resource_dir):
            raise ScenarioError(
                f"{where(display, element)}: {what} source {shown} points outside the .ssp "
                "archive; use a path inside the archive"
            )
        return path

    def open(self, source: str, element: Element, display: str) -> tuple[Element, str]:
        """Parse and validate a file referenced from ``element`` (ssv, ssm, ssb)."""
        path = self.resolve(source, element, display, what="file")
        name = (
            path.relative_to(self.resource_dir).as_posix()
            if path.is_relative_to(self.resource_dir)
            else str(path)
        )
        if not path.is_file():
            raise ScenarioError(
                f"{where(display, element)}: referenced file '{source}' does not exist "
                f"(looked for {path}); add it or fix the source attribute"
            )
        root = parse(path, name)
        warning = validate(root, name)
        if warning:
            self.warnings.append(warning)
        self.warnings.extend(unsupported(root, name))
        return root, name
