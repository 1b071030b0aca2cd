"""Reading SSP XML files safely: a hardened lxml parser, schema validation, element helpers.

The parser never touches the network, never loads a DTD and never expands entities; a
document that declares a DOCTYPE is refused outright. Errors name the file and line.
"""

from __future__ import annotations

import functools
import importlib.util
import re
import threading
from collections.abc import Iterator
from contextvars import ContextVar
from copy import deepcopy
from pathlib import Path

from lxml import etree

from coupler.errors import ScenarioError, ValidationError

Element = etree._Element

#: Root element local name -> XSD file shipped by FMPy (SSP 1.0 schemas only).
_SCHEMAS = {
    "SystemStructureDescription": "SystemStructureDescription.xsd",
    "ParameterSet": "SystemStructureParameterValues.xsd",
    "ParameterMapping": "SystemStructureParameterMapping.xsd",
    "SignalDictionary": "SystemStructureSignalDictionary.xsd",
}

MAX_XML_BYTES = 64 * 1024 * 1024


def _parser() -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_pis=True,
    )


def parse(path: Path, display: str) -> Element:
    """Parse ``path`` (shown as ``display`` in messages) and return its root element."""
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise ScenarioError(f"{display}: cannot read the file ({exc.strerror})") from exc
    if size > MAX_XML_BYTES:
        raise ScenarioError(
            f"{display}: {size} bytes is more than the {MAX_XML_BYTES} bytes an SSP XML file may "
            "have; split the file or check that it is the right one"
        )
    try:
        tree = etree.parse(str(path), _parser())
    except etree.XMLSyntaxError as exc:
        line = exc.lineno if exc.lineno is not None else 0
        raise ScenarioError(
            f"{display} line {line}: malformed XML: {exc.msg}; fix the XML syntax"
        ) from exc
    except OSError as exc:  # lxml: bytes that are invalid in the document's encoding
        raise ScenarioError(
            f"{display}: cannot be read as XML ({exc}); save it as UTF-8 (or in the encoding "
            "its XML declaration names)"
        ) from exc
    if getattr(tree.docinfo, "doctype", ""):
        raise ScenarioError(
            f"{display} line 1: a DOCTYPE declaration is not allowed in SSP files "
            "(entities are never expanded); remove it"
        )
    return tree.getroot()


def _schema_dir() -> Path | None:
    spec = importlib.util.find_spec("fmpy")
    if spec is None or not spec.submodule_search_locations:
        return None
    directory = Path(next(iter(spec.submodule_search_locations))) / "ssp" / "schema"
    return directory if directory.is_dir() else None


@functools.cache
def _schema(filename: str) -> etree.XMLSchema | None:
    directory = _schema_dir()
    if directory is None:
        return None
    doc = etree.parse(str(directory / filename), _parser())
    return etree.XMLSchema(doc)


def validate(root: Element, display: str) -> str | None:
    """Validate ``root`` against its SSP 1.0 XSD.

    Raises ValidationError listing every schema error as ``file line N: message``. Returns a
    warning when no schema applies (another SSP version, or FMPy's schemas are missing), in
    which case only the loader's structural checks apply.
    """
    kind = local(root)
    version = root.get("version", "")
    filename = _SCHEMAS.get(kind)
    if filename is None:
        raise ScenarioError(
            f"{display} line {root.sourceline}: root element '{kind}' is not an SSP document "
            f"(expected one of: {', '.join(_SCHEMAS)})"
        )
    if not version.startswith("1."):
        return (
            f"{display}: no XML schema for SSP version '{version}' is available; "
            "checked structurally only"
        )
    schema = _schema(filename)
    if schema is None:
        return (
            f"{display}: the SSP XSDs (shipped with FMPy) are not installed; "
            "checked structurally only"
        )
    if schema.validate(_without_variables(root)):
        return None
    problems = [
        f"{display} line {e.line}: schema violation: {_with_fix(e.message, root)}"
        for e in schema.error_log  # type: ignore[attr-defined]
    ]
    raise ValidationError(problems, subject=display)


STEP_ANNOTATION = (
    '<ssd:Annotations><ssc:Annotation type="com.avl.model.connect.ssp.task">'
    '<mc:Task xmlns:mc="com.avl.model.connect.ssp.task" stepType="parallel_single_thread" '
    'deltaTime="{step}"/></ssc:Annotation></ssd:Annotations>'
)
"""How an SSD carries its step size (OpenMCx's task annotation in the DefaultExperiment; OpenMCx
requires its stepType: ``parallel_single_thread`` is Jacobi, Coupler's default)."""


def _with_fix(message: str, root: Element) -> str:
    """A schema violation's message, with the fix of one people make often (SSP 1.0 has no
    step size)."""
    if "DefaultExperiment" in message and "'stepSize'" in message:
        experiment = next((e for e in root.iter() if local(e) == "DefaultExperiment"), None)
        step = experiment.get("stepSize", "H") if experiment is not None else "H"
        return (
            f"{message.rstrip('.')}: SSP's DefaultExperiment has no step size; remove stepSize "
            f"and give the step with --step {step}, or in the SSD inside the DefaultExperiment: "
            + STEP_ANNOTATION.format(step=step)
        )
    return message


_VARIABLE = re.compile(r"\$\{[^}:]*(?::-([^}]*))?\}")


def _without_variables(root: Element) -> Element:
    """A copy with ``${VAR:-default}`` in source attributes replaced by its default, ``${VAR}``
    by ``0``.

    ``${...}`` is Coupler's convention in component sources but not a valid xs:anyURI; the
    schema checks the rest of the URI (a scheme such as ``${BRIDGE_SCHEME:-grpc}`` needs its
    default: ``0://`` is no URI).
    """
    if not any("${" in e.get("source", "") for e in root.iter("{*}Component")):
        return root
    copy = deepcopy(root)
    for element in copy.iter("{*}Component"):
        source = element.get("source")
        if source and "${" in source:
            element.set("source", _VARIABLE.sub(lambda m: m.group(1) or "0", source))
    return copy


cancelled: ContextVar[threading.Event | None] = ContextVar("coupler_ssp_cancelled", default=None)
"""Set while a load runs on its thread: the caller sets the event to stop it (Ctrl-C)."""


class LoadCancelled(Exception):
    """The load was stopped through ``cancelled``; its caller is ending the command."""


def checkpoint() -> None:
    """Stop here when the load was cancelled: called per element read and every few thousand
    connectors made, so Ctrl-C ends the load of a large SSD within a fraction of a second."""
    event = cancelled.get()
    if event is not None and event.is_set():
        raise LoadCancelled


def local(element: Element) -> str:
    """The element's tag without its namespace."""
    return etree.QName(element).localname


def children(element: Element, name: str) -> Iterator[Element]:
    """Child elements with local name ``name`` (comments skipped)."""
    for child in element:
        if isinstance(child.tag, str) and local(child) == name:
            checkpoint()
            yield child


def child(element: Element, name: str) -> Element | None:
    """The first child element with local name ``name``, or None."""
    return next(children(element, name), None)


def elements(element: Element) -> Iterator[Element]:
    """All child elements (comments and processing instructions skipped)."""
    for item in element:
        if isinstance(item.tag, str):
            checkpoint()
            yield item


def line_of(element: Element) -> int:
    """The line ``element`` starts on (0 when unknown)."""
    value = element.sourceline
    return value if isinstance(value, int) else 0


def where(display: str, element: Element) -> str:
    """``file line N`` of ``element``."""
    return f"{display} line {line_of(element)}"


def required(element: Element, attribute: str, display: str) -> str:
    """The attribute's value; ScenarioError when it is missing (structural check)."""
    value = element.get(attribute)
    if value is None:
        raise ScenarioError(
            f"{where(display, element)}: <{local(element)}> lacks the required attribute "
            f"'{attribute}'; add it"
        )
    return value


def number(element: Element, attribute: str, display: str, default: float | None) -> float | None:
    """A float attribute, or ``default`` when absent."""
    text = element.get(attribute)
    if text is None:
        return default
    try:
        return float(text)
    except ValueError as exc:
        raise ScenarioError(
            f'{where(display, element)}: <{local(element)} {attribute}="{text}"> '
            "is not a number; write a decimal number"
        ) from exc


def integer(element: Element, attribute: str, display: str, default: int | None) -> int | None:
    """An int attribute, or ``default`` when absent."""
    text = element.get(attribute)
    if text is None:
        return default
    try:
        return int(text)
    except ValueError as exc:
        raise ScenarioError(
            f'{where(display, element)}: <{local(element)} {attribute}="{text}"> '
            "is not an integer; write a whole number"
        ) from exc


def boolean(element: Element, attribute: str, display: str, default: bool) -> bool:
    """An xs:boolean attribute, or ``default`` when absent."""
    text = element.get(attribute)
    if text is None:
        return default
    if text.strip() in ("true", "1"):
        return True
    if text.strip() in ("false", "0"):
        return False
    raise ScenarioError(
        f'{where(display, element)}: <{local(element)} {attribute}="{text}"> '
        "is not a boolean; write true or false"
    )
