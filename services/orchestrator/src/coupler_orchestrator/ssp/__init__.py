"""SSP loading: .ssp archives and bare .ssd files into a flattened, frozen :class:`Scenario`.

load_ssp(path)            -> Scenario   (raises ScenarioError / ValidationError)
check_connections(s)      -> list[str]  structural problems of the wiring
converter(s, connection)  -> Callable[[Value], Value]  unit conversion + transformation
"""

from __future__ import annotations

from .checks import check_connections
from .conversion import converter, identity
from .loader import load_ssp
from .model import (
    FMU_TYPE,
    GRPC_TYPE,
    Backend,
    BaseUnit,
    BooleanMappingTransformation,
    Component,
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

__all__ = [
    "FMU_TYPE",
    "GRPC_TYPE",
    "Backend",
    "BaseUnit",
    "BooleanMappingTransformation",
    "Component",
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
    "check_connections",
    "converter",
    "identity",
    "load_ssp",
]
