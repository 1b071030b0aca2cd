"""``${VAR}`` and ``${VAR:-default}`` expansion in component sources.

Only variables that name where a participant is may be expanded: names ending in ``_HOST``,
``_PORT``, ``_ADDRESS``, ``_SCHEME`` or ``_DIR`` (``BRIDGE_HOST``, ``COUPLER_FMU_DIR``). An SSD
therefore cannot read an arbitrary environment variable (a secret) into an address. A message
about a source quotes it as written and names its variables (``variables_in``), never their
values. Sources may not carry user information (``grpc://user:password@host``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from coupler.errors import ScenarioError

ALLOWED_SUFFIXES = ("_HOST", "_PORT", "_ADDRESS", "_SCHEME", "_DIR")
_PATTERN = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::-([^}]*))?\}")


def expand(text: str, env: Mapping[str, str], *, what: str) -> str:
    """``text`` with every ``${VAR}`` replaced from ``env``.

    ``${VAR:-default}`` uses ``default`` when VAR is unset or empty (as the shell does).
    ``what`` names the culprit (component and file:line) in errors; an error names a variable
    but never shows its value.
    """
    refused = sorted({m.group(1) for m in _PATTERN.finditer(text)} - _allowed(text))
    if refused:
        raise ScenarioError(
            f'{what}: source "{text}" uses the environment variable '
            f"{', '.join(repr(n) for n in refused)}; only names ending in "
            f"{', '.join(ALLOWED_SUFFIXES)} may be used in a source (so that an SSD cannot read "
            f"other variables); rename it, e.g. ${{{refused[0]}_HOST}}"
        )

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

    expanded = _PATTERN.sub(replace, text)
    if "@" in expanded.partition("://")[2].partition("/")[0]:
        raise ScenarioError(
            f'{what}: source "{text}" carries user information (user@host); credentials '
            "never go into an SSD - use a token file (docs/security.md)"
        )
    return expanded


def variables_in(text: str) -> list[str]:
    """The variables ``text`` expands, in order, each once."""
    return list(dict.fromkeys(m.group(1) for m in _PATTERN.finditer(text)))


def _allowed(text: str) -> set[str]:
    return {m.group(1) for m in _PATTERN.finditer(text) if m.group(1).endswith(ALLOWED_SUFFIXES)}
