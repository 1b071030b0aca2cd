"""The smallest FMI 2.0 co-simulation master: Python's standard library and ctypes, nothing
else, for running an FMU where nothing is installed (scripts/export-fmu-check.sh runs it in a
container of the bare base image).

    python3 fmi2_master.py UNZIPPED_FMU --step 0.125 --stop 1 --set u=1.5 --set gain=3 \
        --output y --output x

Prints one line per communication point, ``t=... y=... x=...`` (floats as repr: exact), and
exits 1 with the FMU's log when a call fails.
"""

from __future__ import annotations

import argparse
import ctypes
import sys
from pathlib import Path
from xml.etree import ElementTree

LOGGER = ctypes.CFUNCTYPE(
    None, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p
)
ALLOCATE = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_size_t, ctypes.c_size_t)
FREE = ctypes.CFUNCTYPE(None, ctypes.c_void_p)


class Callbacks(ctypes.Structure):
    _fields_ = [
        ("logger", LOGGER),
        ("allocateMemory", ALLOCATE),
        ("freeMemory", FREE),
        ("stepFinished", ctypes.c_void_p),
        ("componentEnvironment", ctypes.c_void_p),
    ]


def log(env: int, name: bytes, status: int, category: bytes, message: bytes) -> None:
    print(f"[{category.decode()}] {message.decode().replace('%%', '%')}", file=sys.stderr)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("fmu", type=Path, help="the unzipped FMU")
    parser.add_argument("--step", type=float, required=True)
    parser.add_argument("--stop", type=float, required=True)
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    parser.add_argument("--output", action="append", default=[], metavar="NAME")
    args = parser.parse_args()

    root = ElementTree.parse(args.fmu / "modelDescription.xml").getroot()
    identifier = root.find("CoSimulation").get("modelIdentifier")  # type: ignore[union-attr]
    variables = {}
    for variable in root.iter("ScalarVariable"):
        kind = next(iter(variable)).tag
        variables[variable.get("name")] = (int(variable.get("valueReference")), kind)
    fmu = ctypes.CDLL(str(args.fmu / "binaries" / "linux64" / f"{identifier}.so"))
    libc = ctypes.CDLL(None)
    libc.calloc.restype = ctypes.c_void_p
    libc.calloc.argtypes = [ctypes.c_size_t, ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    callbacks = Callbacks(LOGGER(log), ALLOCATE(libc.calloc), FREE(libc.free), None, None)
    fmu.fmi2Instantiate.restype = ctypes.c_void_p
    fmu.fmi2Instantiate.argtypes = [
        ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p,
        ctypes.POINTER(Callbacks), ctypes.c_int, ctypes.c_int,
    ]  # fmt: skip
    resources = (args.fmu / "resources").resolve().as_uri().encode()
    instance = fmu.fmi2Instantiate(
        b"instance", 1, root.get("guid").encode(), resources, ctypes.byref(callbacks), 0, 0
    )
    if not instance:
        print("fmi2Instantiate failed", file=sys.stderr)
        return 1
    c = ctypes.c_void_p(instance)

    def check(status: int, call: str) -> None:
        if status > 1:  # fmi2Discard and worse
            print(f"{call} failed with status {status}", file=sys.stderr)
            sys.exit(1)

    for item in args.set:
        name, _, text = item.partition("=")
        vr, kind = variables[name]
        refs = (ctypes.c_uint * 1)(vr)
        if kind == "Real":
            check(fmu.fmi2SetReal(c, refs, 1, (ctypes.c_double * 1)(float(text))), "SetReal")
        elif kind == "String":
            check(fmu.fmi2SetString(c, refs, 1, (ctypes.c_char_p * 1)(text.encode())), "Set")
        else:
            value = int(text == "true") if kind == "Boolean" else int(text)
            setter = fmu.fmi2SetBoolean if kind == "Boolean" else fmu.fmi2SetInteger
            check(setter(c, refs, 1, (ctypes.c_int * 1)(value)), f"Set{kind}")
    fmu.fmi2SetupExperiment.argtypes = [
        ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.c_double, ctypes.c_int,
        ctypes.c_double,
    ]  # fmt: skip
    check(fmu.fmi2SetupExperiment(c, 0, 0.0, 0.0, 1, args.stop), "SetupExperiment")
    check(fmu.fmi2EnterInitializationMode(c), "EnterInitializationMode")
    check(fmu.fmi2ExitInitializationMode(c), "ExitInitializationMode")
    fmu.fmi2DoStep.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    steps = round(args.stop / args.step)
    for k in range(steps + 1):
        values = []
        for name in args.output:
            vr, _ = variables[name]
            value = (ctypes.c_double * 1)()
            check(fmu.fmi2GetReal(c, (ctypes.c_uint * 1)(vr), 1, value), "GetReal")
            values.append(f"{name}={value[0]!r}")
        print(f"t={k * args.step!r} " + " ".join(values), flush=True)
        if k < steps:
            check(fmu.fmi2DoStep(c, k * args.step, args.step, 1), "DoStep")
    check(fmu.fmi2Terminate(c), "Terminate")
    fmu.fmi2FreeInstance.argtypes = [ctypes.c_void_p]
    fmu.fmi2FreeInstance(c)
    return 0


if __name__ == "__main__":
    sys.exit(main())
