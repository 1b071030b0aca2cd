"""SSP reading: .ssp archives, unpacked SSP folders and bare .ssd files into a flattened,
frozen :class:`Scenario` (reading only: checking against participants, wiring and running are
later stages of the orchestrator).

load_ssp(path)      -> Scenario   (raises ScenarioError / ValidationError)
scenario_of_fmu(p)  -> Scenario   one FMU alone, from its modelDescription
"""

from __future__ import annotations

from .loader import load_ssp
from .model import (
    FMU_TYPE,
    GRPC_TYPE,
    REPLAY_SCHEME,
    Backend,
    BaseUnit,
    BooleanMappingTransformation,
    Component,
    ComponentSettings,
    Connection,
    Connector,
    DictionaryEntry,
    Enumeration,
    EnumerationMappingTransformation,
    IntegerMappingTransformation,
    LinearTransformation,
    ParameterValue,
    Results,
    Scenario,
    SignalDictionary,
    Task,
    Transformation,
    Unit,
)
from .single import scenario_of_fmu

__all__ = [
    "FMU_TYPE",
    "GRPC_TYPE",
    "REPLAY_SCHEME",
    "Backend",
    "BaseUnit",
    "BooleanMappingTransformation",
    "Component",
    "ComponentSettings",
    "Connection",
    "Connector",
    "DictionaryEntry",
    "Enumeration",
    "EnumerationMappingTransformation",
    "IntegerMappingTransformation",
    "LinearTransformation",
    "ParameterValue",
    "Results",
    "Scenario",
    "SignalDictionary",
    "Task",
    "Transformation",
    "Unit",
    "load_ssp",
    "scenario_of_fmu",
]
