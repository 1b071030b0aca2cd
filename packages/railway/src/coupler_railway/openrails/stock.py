"""Placeholder rolling stock and a consist, so OpenRails' Explore mode has a train.

``TRAINS/TRAINSET/CouplerBR642/`` holds one engine (``CouplerBR642A.eng``, a powered car) and
one wagon (``CouplerBR642B.wag``, a trailer car), each a box shape with single-colour textures
beside it; ``TRAINS/CONSISTS/CouplerBR642.con`` couples them. The figures are the mock's
regional train (``openrails_mock.physics.DB_CLASS_642``): two 20.85 m cars, 75 t, 500 kW at the
wheel, 100 kN. It is PLACEHOLDER stock: no cab, no sound, no lights, no animation; the
engine and wagon files carry the handful of values a train needs to move (type, shape, size,
mass, wheels, coupling, brakes, power, force), with everything else left to OpenRails'
defaults. OpenRails finds consists and stock in the content folder's ``TRAINS`` (two folders
above the route), so the route's ``TRAINS`` folder is copied there (docs/openrails-route.md).
"""

from __future__ import annotations

from pathlib import Path

from coupler_railway.openrails.ace import write_ace
from coupler_railway.openrails.shapes import COLOURS, save_shape, vehicle
from coupler_railway.openrails.stf import StfWriter, quote

FOLDER = "CouplerBR642"
CONSIST = "CouplerBR642"
ENGINE = "CouplerBR642A"
WAGON = "CouplerBR642B"
CAR_LENGTH_M = 20.85
CAR_MASS_T = 37.5
WIDTH_M, HEIGHT_M = 2.9, 3.9


def _vehicle(stf: StfWriter, name: str, kind: str, title: str) -> None:
    stf.block("Wagon", name)
    stf.line("Type", kind)
    stf.line("WagonShape", f"{name}.s")
    stf.line("Size", f"{WIDTH_M}m", f"{HEIGHT_M}m", f"{CAR_LENGTH_M}m")
    stf.line("Mass", f"{CAR_MASS_T}t")
    stf.line("WheelRadius", "0.385m")
    stf.line("NumWheels", 4)
    stf.block("Coupling")
    stf.line("Type", "Automatic")
    stf.block("Spring")
    stf.line("Stiffness", "1e6N/m", "5e6N/m")
    stf.line("Break", "1e7N", "1e7N")
    stf.line("r0", "0.1m", "0.2m")
    stf.end()
    stf.line("CouplingHasRigidConnection", 1)
    stf.end()
    stf.line("BrakeSystemType", quote("Air_single_pipe"))
    stf.line("MaxBrakeForce", "75kN")
    stf.line("Name", quote(title))
    stf.end()


def write_stock(folder: Path) -> list[str]:
    """The consist, its engine and wagon, their shapes and textures; returns the files."""
    trainset = folder / "TRAINS" / "TRAINSET" / FOLDER
    written = []
    for name, kind, colour, title in (
        (ENGINE, "Engine", "CouplerRed.ace", "Coupler placeholder powered car"),
        (WAGON, "Carriage", "CouplerBlue.ace", "Coupler placeholder trailer car"),
    ):
        shape = vehicle(CAR_LENGTH_M, WIDTH_M, HEIGHT_M, colour)
        save_shape(trainset / f"{name}.s", shape)
        written.append(f"{name}.s")
        for texture in shape.textures:
            write_ace(trainset / texture, COLOURS[texture])
            written.append(texture)
        stf = StfWriter("JINX0D0t")
        _vehicle(stf, name, kind, title)
        if kind == "Engine":
            stf.block("Engine", name)
            stf.line("Type", "Diesel")
            stf.line("MaxPower", "500kW")
            stf.line("MaxForce", "100kN")
            stf.line("MaxContinuousForce", "80kN")
            stf.line("MaxVelocity", "120km/h")
            stf.line("MaxCurrent", "1000A")
            stf.line("Name", quote(title))
            stf.line("Description", quote("Placeholder stock written by coupler-railway"))
            stf.end()
            stf.save(trainset / f"{name}.eng")
            written.append(f"{name}.eng")
        else:
            stf.save(trainset / f"{name}.wag")
            written.append(f"{name}.wag")
    stf = StfWriter("JINX0D0t")
    stf.block("Train")
    stf.block("TrainCfg", CONSIST)
    stf.line("Name", quote("Coupler placeholder regional train (2 cars)"))
    stf.line("Serial", 1)
    stf.line("MaxVelocity", 33.3333, 0.5)
    stf.line("NextWagonUID", 2)
    stf.line("Durability", 1)
    stf.block("Engine")
    stf.line("UiD", 0)
    stf.line("EngineData", ENGINE, FOLDER)
    stf.end()
    stf.block("Wagon")
    stf.line("UiD", 1)
    stf.line("WagonData", WAGON, FOLDER)
    stf.end()
    stf.end()
    stf.end()
    stf.save(folder / "TRAINS" / "CONSISTS" / f"{CONSIST}.con")
    stock = sorted(f"TRAINS/TRAINSET/{FOLDER}/{name}" for name in set(written))
    return [f"TRAINS/CONSISTS/{CONSIST}.con", *stock]
