"""``${VAR}`` and ``${VAR:-default}`` expansion in component sources."""

from __future__ import annotations

import re
from collections.abc import Mapping

from coupler.errors import ScenarioError

_PATTERN = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::-([^}]*))?\}")


def expand(text: str, env: Mapping[str, str], *, what: str) -> str:
    """``text`` with every ``${VAR}`` replaced from ``env``.

    ``${VAR:-default}`` uses ``default`` when VAR is unset or empty (as the shell does).
    ``what`` names the culprit (component and file:line) in the error for an unset VAR.
    """

    def replace(match: re.Match[str]) -> str:
        name, default = match.group(1), match.group(2)
        value = env.get(name)
        if value:
            return value
        if default is not None:
            return default
        if value is not None:
            return value
        raise ScenarioError(
            f"{what}: environment variable '{name}' in source \"{text}\" is not set; "
            f"set {name} or write ${{{name}:-default}}"
        )

    return _PATTERN.sub(replace, text)
