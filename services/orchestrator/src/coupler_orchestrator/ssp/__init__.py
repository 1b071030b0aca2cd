"""SSP reading: .ssp archives, unpacked SSP folders and bare .ssd files into a flattened,
frozen :class:`Scenario` (reading only: checking against participants, wiring and running are
later stages of the orchestrator).

load_ssp(path)      -> Scenario   (raises ScenarioError / ValidationError)
scenario_of_fmu(p)  -> Scenario   one FMU alone, from its modelDescription
"""

from __future__ import annotations

from .loader import load_ssp
from .model import (
    BUILTIN_TYPES,
    FMU_TYPE,
    GRPC_TYPE,
    REPLAY_SCHEME,
    Backend,
    BaseUnit,
    BooleanMappingTransformation,
    Builtin,
    Component,
    ComponentSettings,
    Connection,
    Connector,
    Constant,
    DictionaryEntry,
    Enumeration,
    EnumerationMappingTransformation,
    IntegerMappingTransformation,
    Integrator,
    InterExtrapolation,
    LinearTransformation,
    ParameterValue,
    Port,
    Results,
    Scenario,
    SignalDictionary,
    Task,
    Transformation,
    Unit,
    VectorIntegrator,
)
from .single import scenario_of_fmu

__all__ = [
    "BUILTIN_TYPES",
    "FMU_TYPE",
    "GRPC_TYPE",
    "REPLAY_SCHEME",
    "Backend",
    "BaseUnit",
    "BooleanMappingTransformation",
    "Builtin",
    "Component",
    "ComponentSettings",
    "Connection",
    "Connector",
    "Constant",
    "DictionaryEntry",
    "Enumeration",
    "EnumerationMappingTransformation",
    "IntegerMappingTransformation",
    "Integrator",
    "InterExtrapolation",
    "LinearTransformation",
    "ParameterValue",
    "Port",
    "Results",
    "Scenario",
    "SignalDictionary",
    "Task",
    "Transformation",
    "Unit",
    "VectorIntegrator",
    "load_ssp",
    "scenario_of_fmu",
]
