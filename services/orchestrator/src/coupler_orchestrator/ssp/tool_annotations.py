"""Annotations the loader understands: OpenMCx's (``com.avl.model.connect.ssp.*``) and Coupler's.

OpenMCx names (from its schemas in eclipse/openmcx ``scripts/SSP``):

- DefaultExperiment, ``com.avl.model.connect.ssp.task``: ``<Task stepType deltaTime endType
  sumTime inputAtEndTime relativeEps timingOutput/>``
- DefaultExperiment, ``com.avl.model.connect.ssp.results``: ``<Results outputDirectory
  resultLevel><Backends><Backend type storeAtRuntime/></Backends></Results>``
- Component/System, ``com.avl.model.connect.ssp.component``: ``<Component deltaTime
  triggerSequence inputAtEndTime/>``
- Connection, ``com.avl.model.connect.ssp.connection.decoupling``: ``<Decoupling>`` with one of
  ``<Never/>``, ``<Always/>``, ``<IfNeeded priority="N"/>``
- ports, vector connectors, slices, inter/extrapolation and the built-ins' specific data:
  ``openmcx``

Attributes of OpenMCx's annotations are checked against its schemas: an unknown one is an error
naming the file and line, and so is an OpenMCx annotation Coupler cannot apply and that would
change values (``openmcx.REFUSED``) or does not know.

Coupler's own: Connection, ``org.coupler.connection``: ``<coupler:Connection decoupled="true"/>``;
Component, ``org.coupler.component``: ``<coupler:Component isolate="true" callTimeout="5"
tlsCa="..." tlsCert="..." tlsKey="..." tokenFile="..."/>`` (paths relative to the SSD; secrets
are never written inline).
Every other annotation is reported as a warning by :func:`unsupported`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

from coupler import durations
from coupler.errors import ScenarioError

from . import openmcx
from .documents import Element, boolean, child, children, elements, integer, local, number, where
from .model import Backend, ComponentSettings, Results, Task

TASK = "com.avl.model.connect.ssp.task"
RESULTS = "com.avl.model.connect.ssp.results"
COMPONENT = "com.avl.model.connect.ssp.component"
DECOUPLING = "com.avl.model.connect.ssp.connection.decoupling"
COUPLER_CONNECTION = "org.coupler.connection"
COUPLER_COMPONENT = "org.coupler.component"
_SETTING_PATHS = {"tlsCa": "tls_ca", "tlsCert": "tls_cert", "tlsKey": "tls_key"}
_SETTING_PATHS["tokenFile"] = "token_file"

#: (owner element local name, annotation type) pairs the loader applies.
HANDLED = {
    ("DefaultExperiment", TASK),
    ("DefaultExperiment", RESULTS),
    ("Component", COMPONENT),
    ("Connection", DECOUPLING),
    ("Connection", COUPLER_CONNECTION),
    ("Component", COUPLER_COMPONENT),
    ("Connector", openmcx.PORT),
    ("Connection", openmcx.CONNECTION),
    ("Connection", openmcx.INTER_EXTRAPOLATION),
    *(("Component", kind) for kind in openmcx.SPECIFIC_DATA.values()),
}

STEP_TYPES = ("sequential", "parallel_single_thread", "parallel_one_step_size", "parallel_sync_all")
END_TYPES = ("end_time", "first_component")


def annotation(owner: Element, kind: str) -> Element | None:
    """The content element of ``owner``'s annotation of type ``kind``, or None."""
    annotations = child(owner, "Annotations")
    if annotations is None:
        return None
    for item in children(annotations, "Annotation"):
        if item.get("type") == kind:
            return next(elements(item), None)
    return None


def read_task(experiment: Element, display: str, warnings: list[str]) -> Task | None:
    """OpenMCx task settings of a DefaultExperiment."""
    task = annotation(experiment, TASK)
    if task is None:
        return None
    here = where(display, task)
    openmcx.attributes(
        task,
        (
            "stepType",
            "deltaTime",
            "endType",
            "sumTime",
            "inputAtEndTime",
            "relativeEps",
            "timingOutput",
        ),
        display,
    )
    step_type = openmcx.required_attribute(task, "stepType", display)
    if step_type not in STEP_TYPES:
        raise ScenarioError(
            f"{here}: OpenMCx stepType '{step_type}' is not one of {', '.join(STEP_TYPES)}"
        )
    end_type = task.get("endType", "end_time")
    if end_type not in END_TYPES:
        raise ScenarioError(
            f"{here}: OpenMCx endType '{end_type}' is not one of {', '.join(END_TYPES)}"
        )
    result = Task(
        step_type=step_type,
        delta_time=number(task, "deltaTime", display, 0.01) or 0.0,
        end_type=end_type,
        sum_time=boolean(task, "sumTime", display, False),
        input_at_end_time=boolean(task, "inputAtEndTime", display, False),
        relative_eps=number(task, "relativeEps", display, 1e-10) or 0.0,
        timing_output=boolean(task, "timingOutput", display, False),
    )
    for attr, set_, meaning in (
        ("sumTime", result.sum_time, "communication points are exact: t0 + k*h"),
        ("inputAtEndTime", result.input_at_end_time, "OpenMCx itself reads it and does nothing"),
        ("timingOutput", result.timing_output, "summary.json has each member's latency"),
    ):
        if set_:
            warnings.append(f'{here}: OpenMCx task attribute {attr}="true" is ignored: {meaning}')
    return result


def read_results(experiment: Element, display: str, warnings: list[str]) -> Results | None:
    """OpenMCx results settings of a DefaultExperiment; what Coupler does not apply is warned."""
    results = annotation(experiment, RESULTS)
    if results is None:
        return None
    backends = child(results, "Backends")
    here = f"{display} line {results.sourceline}"
    level = results.get("resultLevel", "synchronization")
    if level != "synchronization":
        warnings.append(
            f"{here}: OpenMCx resultLevel '{level}' is not supported; Coupler records every "
            f"communication point (synchronization)"
        )
    for backend in children(backends, "Backend") if backends is not None else ():
        if backend.get("type", "").lower() != "csv":
            warnings.append(
                f"{here}: OpenMCx results backend '{backend.get('type', '')}' is not supported; "
                f"Coupler writes results.csv and summary.json"
            )
    return Results(
        output_directory=results.get("outputDirectory"),
        result_level=results.get("resultLevel", "synchronization"),
        backends=tuple(
            Backend(
                type=b.get("type", ""),
                store_at_runtime=boolean(b, "storeAtRuntime", display, True),
            )
            for b in (children(backends, "Backend") if backends is not None else ())
        ),
    )


def component_task(component: Element, display: str) -> tuple[float | None, bool, int]:
    """(deltaTime, inputAtEndTime, triggerSequence) of a component (OpenMCx component
    annotation); (None, False, -1) without one."""
    settings = annotation(component, COMPONENT)
    if settings is None:
        return None, False, -1
    openmcx.attributes(settings, ("deltaTime", "inputAtEndTime", "triggerSequence"), display)
    sequence = integer(settings, "triggerSequence", display, -1)
    return (
        number(settings, "deltaTime", display, None),
        boolean(settings, "inputAtEndTime", display, False),
        -1 if sequence is None else sequence,
    )


def component_settings(
    component: Element, display: str, resolve: Callable[[str, str], Path]
) -> ComponentSettings:
    """Coupler's own settings of a component; ``resolve(source, what)`` locates a file."""
    settings = annotation(component, COUPLER_COMPONENT)
    if settings is None:
        return ComponentSettings()
    known = {"isolate", "callTimeout", *_SETTING_PATHS}
    unknown = sorted(set(settings.attrib) - known)
    if unknown:
        raise ScenarioError(
            f"{where(display, settings)}: {COUPLER_COMPONENT} has no setting "
            f"{', '.join(repr(u) for u in unknown)} (settings: {', '.join(sorted(known))})"
        )
    timeout = number(settings, "callTimeout", display, None)
    if timeout is not None and (why := durations.problem(timeout, durations.MAX_TIMEOUT)):
        raise ScenarioError(f"{where(display, settings)}: callTimeout {why}")
    paths = {
        field: resolve(text, attribute)
        for attribute, field in _SETTING_PATHS.items()
        if (text := settings.get(attribute))
    }
    isolate = settings.get("isolate")
    return ComponentSettings(
        isolate=None if isolate is None else boolean(settings, "isolate", display, False),
        call_timeout=timeout,
        **paths,
    )


def decoupling(connection: Element, display: str) -> tuple[bool, str | None, int | None]:
    """(decoupled, decouple_type, decouple_priority) of a Connection."""
    ours = annotation(connection, COUPLER_CONNECTION)
    if ours is not None and boolean(ours, "decoupled", display, False):
        return True, "always", None
    theirs = annotation(connection, DECOUPLING)
    if theirs is None:
        return False, None, None
    openmcx.attributes(theirs, (), display)
    choice = list(elements(theirs))
    if len(choice) != 1 or local(choice[0]) not in ("Never", "Always", "IfNeeded"):
        raise ScenarioError(
            f"{where(display, theirs)}: <mc:Decoupling> holds exactly one of <mc:Never/>, "
            '<mc:Always/>, <mc:IfNeeded priority="N"/>'
        )
    item = choice[0]
    name = local(item)
    openmcx.attributes(item, ("priority",) if name == "IfNeeded" else (), display)
    if name == "Never":
        return False, "never", None
    if name == "Always":
        return True, "always", None
    priority = integer(item, "priority", display, 0)
    if priority is not None and priority < 0:
        raise ScenarioError(f'{where(display, item)}: priority="{priority}" must not be negative')
    return False, "if_needed", priority


def unsupported(root: Element, display: str) -> Iterator[str]:
    """A warning for every annotation in the document the loader does not apply (OpenMCx's
    that change no value among them; ``refused`` names those it cannot)."""
    for item, owner, kind in _annotations(root):
        if (local(owner), kind) in HANDLED or _openmcx_refusal(kind):
            continue
        label = owner.get("name") or owner.get("startConnector") or ""
        name = f" '{label}'" if label else ""
        why = openmcx.IGNORED.get(kind, "")
        yield (
            f"{where(display, item)}: annotation '{kind}' on <{local(owner)}>{name} "
            f"is not supported; ignored{f' ({why})' if why else ''}"
        )


def refused(root: Element, display: str) -> Iterator[str]:
    """A problem for every OpenMCx annotation Coupler cannot apply where it would change
    values, and for every one OpenMCx does not define."""
    for item, owner, kind in _annotations(root):
        if (local(owner), kind) in HANDLED:
            continue
        reason = _openmcx_refusal(kind)
        if reason:
            yield f"{where(display, item)}: annotation '{kind}' on <{local(owner)}>: {reason}"


def _openmcx_refusal(kind: str) -> str:
    if not kind.startswith(openmcx.PREFIX) or kind in openmcx.IGNORED:
        return ""
    known = {TASK, RESULTS, COMPONENT, DECOUPLING, openmcx.PORT, openmcx.CONNECTION}
    known |= {openmcx.INTER_EXTRAPOLATION, *openmcx.SPECIFIC_DATA.values()}
    if kind in known:
        return "OpenMCx reads it only on another element; move it"
    return openmcx.REFUSED.get(kind, "OpenMCx defines no such annotation; fix its type")


def _annotations(root: Element) -> Iterator[tuple[Element, Element, str]]:
    for item in root.iter("{*}Annotation"):
        annotations = item.getparent()
        owner = annotations.getparent() if annotations is not None else None
        if owner is not None:
            yield item, owner, item.get("type", "")
