"""The package's one exception.

ValueError
 └── RailMLError   bad or unsupported railML input: names file:line, element and the fix
"""

from __future__ import annotations


class RailMLError(ValueError):
    """A railML file that cannot be turned into an infrastructure model."""

    def __init__(
        self, file: str, line: int | None, element: str | None, problem: str, fix: str
    ) -> None:
        self.file = file
        """Path of the railML file as given."""
        self.line = line
        """1-based line of the culprit, None when unknown."""
        self.element = element
        """The culprit element, e.g. ``<balise id="b3">``; None for file-level errors."""
        self.problem = problem
        self.fix = fix
        where = f"{file}:{line}" if line is not None else file
        culprit = f" {element}:" if element else ""
        super().__init__(f"{where}:{culprit} {problem}; {fix}")
