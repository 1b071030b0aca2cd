"""``load_ssp``: an .ssp archive, an unpacked SSP folder or a bare .ssd into a flattened
:class:`Scenario`.

Steps: extract (archives) -> parse with the hardened parser -> schema-validate -> walk the
system tree (``system``) -> flatten connections through nested systems and signal dictionaries
(``graph``) -> resolve parameter bindings (``parameters``). Every problem found along the way is
collected and raised together as a ValidationError; everything the loader does not apply is
reported in ``Scenario.warnings``.
"""

from __future__ import annotations

import hashlib
import os
import threading
import zipfile
from collections.abc import Mapping
from pathlib import Path

from coupler.archives import Budget
from coupler.errors import ScenarioError, ValidationError

from . import archive, documents, openmcx
from . import tool_annotations as notes
from .documents import child, local, number, parse, required, validate
from .files import Documents
from .model import Scenario, frozen_mapping
from .parameters import apply_bindings, read_enumerations
from .system import SystemReader
from .units import UndefinedUnits, read_units


def load_ssp(
    path: str | Path,
    *,
    env: Mapping[str, str] | None = None,
    workdir: Path | None = None,
    max_archive_bytes: int = archive.MAX_EXTRACTED_BYTES,
    budget: Budget | None = None,
    cancelled: threading.Event | None = None,
) -> Scenario:
    """Load an .ssp archive, a folder holding an unpacked one, or a bare .ssd.

    ``env`` expands ``${VAR}`` in component sources (default: ``os.environ``; only the names
    ``expansion`` allows). Archives are extracted into ``workdir``, which the caller owns and
    removes (``runner`` does, on every path); without one, loading an archive is an error.
    ``budget`` (default: ``max_archive_bytes``) is what the archive may unpack to; the runner
    shares it with the FMUs. ``cancelled`` stops the load where it is (an extraction between
    chunks, the reading between elements): ``LoadCancelled``.
    """
    token = documents.cancelled.set(cancelled)
    try:
        return _load_ssp(path, env, workdir, max_archive_bytes, budget, cancelled)
    finally:
        documents.cancelled.reset(token)


def _load_ssp(
    path: str | Path,
    env: Mapping[str, str] | None,
    workdir: Path | None,
    max_archive_bytes: int,
    budget: Budget | None,
    cancelled: threading.Event | None,
) -> Scenario:
    given = Path(path)
    source = given.resolve()
    if source.is_dir():
        ssd = source / archive.SSD_NAME
        if not ssd.is_file():
            raise ScenarioError(
                f"{given}: a folder given as a scenario must hold an unpacked SSP with "
                f"{archive.SSD_NAME} at its top; give that folder, an .ssp or an .ssd file"
            )
        return _load(ssd, _digest(ssd), ssd, source, env, confined=True)
    if not source.is_file():
        raise ScenarioError(
            f"{given}: no such file; give the path of an .ssp or .ssd file (or an unpacked "
            "SSP folder, or an .fmu)"
        )
    digest = _digest(source)
    if source.suffix.lower() == ".ssd":
        return _load(source, digest, source, source.parent, env, confined=False)
    if source.suffix.lower() != ".ssp" and not zipfile.is_zipfile(source):
        raise ScenarioError(
            f"{source.name}: expected an .ssp archive, an .ssd file, an unpacked SSP folder or "
            "an .fmu"
        )
    if workdir is None:
        raise ScenarioError(f"{source.name}: an archive needs a directory to be extracted into")
    ssd = archive.extract(
        source, workdir, budget=budget or Budget.of(max_archive_bytes), cancelled=cancelled
    )
    return _load(source, digest, ssd, workdir.resolve(), env, confined=True)


def _digest(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as file:
        for chunk in iter(lambda: file.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _load(
    source: Path,
    digest: str,
    ssd: Path,
    resource_dir: Path,
    env: Mapping[str, str] | None,
    *,
    confined: bool,
) -> Scenario:
    display = ssd.name
    warnings: list[str] = []
    problems: list[str] = []
    root = parse(ssd, display)
    if local(root) != "SystemStructureDescription":
        raise ScenarioError(
            f"{display} line {root.sourceline}: root element is <{local(root)}>, "
            "expected <ssd:SystemStructureDescription>"
        )
    schema_note = validate(root, display)
    if schema_note:
        warnings.append(schema_note)
    version = required(root, "version", display)
    if not (version.startswith("1.") or version.startswith("2.")):
        warnings.append(
            f"{display}: SSP version '{version}' is neither 1.x nor 2.x; loaded as SSP 1.0"
        )
    warnings.extend(notes.unsupported(root, display))
    problems.extend(notes.refused(root, display))
    units = read_units(child(root, "Units"), display)
    enumerations = read_enumerations(child(root, "Enumerations"), display)
    system = child(root, "System")
    if system is None:
        raise ScenarioError(f"{display} line {root.sourceline}: no <ssd:System>; add one")
    undefined = UndefinedUnits(problems)
    reader = SystemReader(
        display,
        Documents(resource_dir, confined=confined, warnings=warnings),
        units=units,
        enumerations=enumerations,
        env=os.environ if env is None else env,
        warnings=warnings,
        problems=problems,
        undefined=undefined,
    )
    reader.walk(system, ())
    tree = reader.tree
    connections = tree.graph.flatten(tree.components, warnings, problems)
    components = apply_bindings(
        tree.components,
        tree.systems,
        tree.bindings,
        units,
        warnings=warnings,
        problems=problems,
        undefined=undefined,
    )
    start, stop, task, results = None, None, None, None
    experiment = child(root, "DefaultExperiment")
    if experiment is not None:
        start = number(experiment, "startTime", display, None)
        stop = number(experiment, "stopTime", display, None)
        try:
            task = notes.read_task(experiment, display, warnings)
            results = notes.read_results(experiment, display, warnings)
        except ScenarioError as exc:
            problems.append(str(exc))
    if problems:
        raise ValidationError(problems, subject=display)
    return Scenario(
        source=source,
        sha256=digest,
        ssp_version=version,
        name=root.get("name", ""),
        components=components,
        connections=tuple(connections),
        units=frozen_mapping(units),
        enumerations=frozen_mapping(enumerations),
        signal_dictionaries=frozen_mapping({".".join(k): v for k, v in tree.dictionaries.items()}),
        start_time=start,
        stop_time=stop,
        step_size=task.delta_time if task else None,
        step_type=task.step_type if task else None,
        task=task,
        results=results,
        warnings=tuple(warnings),
        resource_dir=resource_dir,
        openmcx=openmcx.semantics_reason(root, display),
    )
