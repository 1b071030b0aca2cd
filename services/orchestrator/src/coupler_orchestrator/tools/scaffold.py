"""``coupler new participant NAME``: a folder holding a participant that runs as it is.

The folder holds ``participant.py`` (a complete program: imports, channel declarations, the
step, ``serve_main``: every option ``coupler fleet`` passes, ``--port``, ``--socket``, ...),
``NAME.ssd`` (the participant alone, a stop time, its parameter and input bound), ``fleet.toml``
(``coupler fleet`` starts the program and runs the SSD) and ``README.md`` (how to run them and
what to edit). Two templates (``TEMPLATES``): ``integrator`` (gain and integrator in m/s and m,
units declared in ``<ssd:Units>``, the step in OpenMCx's task annotation) and ``minimal`` (one
parameter, one input, one output, no units). The SSD reaches the participant at
``grpc://${NAME_HOST:-127.0.0.1}:${NAME_PORT:-PORT}``, so the port chosen here is only the
default. docs/participants.md explains every part.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from coupler.errors import CouplerError

NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}")
"""What a participant NAME may be: a component name, a Python class name and, upper-cased, the
start of an environment variable's name."""
DEFAULT_PORT = 50080
DEFAULT_TEMPLATE = "integrator"


class ScaffoldError(CouplerError):
    """The folder cannot be written as asked (a wrong NAME, an existing folder)."""


@dataclass(frozen=True)
class Scaffold:
    """What ``write_participant`` wrote."""

    folder: Path
    program: Path
    ssd: Path
    fleet: Path
    readme: Path
    variable: str
    """The environment variable that moves the SSD's port, e.g. ``HEATER_PORT``."""


@dataclass(frozen=True)
class Template:
    """The files of one kind of participant (``@NAME@``, ``@PORT@``, ... replaced)."""

    summary: str
    """What it is, for ``coupler new participant --help``."""
    program: str
    ssd: str
    edit: str
    """The README's "What to edit" list."""


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a participant, or None."""
    if NAME.fullmatch(name):
        return None
    return (
        f"{name!r} cannot name a participant: use a letter, then letters, digits or _ (at most "
        f"64), e.g. Heater; it names the component, the class and the variable NAME_PORT"
    )


def write_participant(
    name: str, folder: Path, *, port: int = DEFAULT_PORT, template: str = DEFAULT_TEMPLATE
) -> Scaffold:
    """Write the participant ``name`` into the new folder ``folder`` from ``template`` (a key
    of ``TEMPLATES``); refuse an existing folder."""
    if why := name_problem(name):
        raise ScaffoldError(why)
    if not 1 <= port <= 65535:
        raise ScaffoldError(f"--port {port}: a port is 1 to 65535")
    chosen = TEMPLATES.get(template)
    if chosen is None:
        raise ScaffoldError(f"--template {template!r}: choose one of {', '.join(TEMPLATES)}")
    if folder.exists():
        raise ScaffoldError(
            f"{folder} exists; coupler new writes a new folder: remove it or give another "
            f"with --dir"
        )
    variable = f"{name.upper()}_PORT"
    words = {
        "@EDIT@": chosen.edit,
        "@NAME@": name,
        "@CLASS@": f"{name[0].upper()}{name[1:]}Participant",
        "@PORT@": str(port),
        "@HOST_VARIABLE@": f"{name.upper()}_HOST",
        "@PORT_VARIABLE@": variable,
    }
    try:
        folder.mkdir(parents=True)
        program = _write(folder / "participant.py", chosen.program, words)
        ssd = _write(folder / f"{name}.ssd", chosen.ssd, words)
        fleet = _write(folder / "fleet.toml", FLEET, words)
        readme = _write(folder / "README.md", README, words)
    except OSError as exc:
        raise ScaffoldError(f"cannot write {exc.filename or folder}: {exc.strerror}") from exc
    return Scaffold(
        folder=folder, program=program, ssd=ssd, fleet=fleet, readme=readme, variable=variable
    )


def _write(path: Path, template: str, words: dict[str, str]) -> Path:
    text = template
    for word, value in words.items():
        text = text.replace(word, value)
    path.write_text(text, encoding="utf-8")
    return path


INTEGRATOR_PROGRAM = '''\
"""@NAME@: a Coupler participant (written by `coupler new participant @NAME@`).

Per step from t to t + h, with the inputs held over the step:

    y = gain * u         [m/s]
    x = x + y * h        [m]    (x starts at the parameter x0)

Serve it with `python participant.py --port @PORT@` (`--help`: every option, `--socket PATH`
as `coupler fleet` gives it, TLS, ...); `coupler run @NAME@.ssd` drives it. Edit CHANNELS and
the step; README.md says what else, docs/participants.md explains every part.
"""

from __future__ import annotations

from collections.abc import Mapping

from coupler import (
    Causality,
    Channel,
    Description,
    Participant,
    RunSetup,
    Value,
    Values,
    ValueType,
    serve_main,
)

CHANNELS = (
    Channel(
        name="gain",
        causality=Causality.PARAMETER,
        type=ValueType.REAL,
        start=1.0,
        description="factor of y",
    ),
    Channel(
        name="x0",
        causality=Causality.PARAMETER,
        type=ValueType.REAL,
        unit="m",
        start=0.0,
        description="x at the start",
    ),
    Channel(
        name="u",
        causality=Causality.INPUT,
        type=ValueType.REAL,
        unit="m/s",
        start=0.0,
        description="the input",
    ),
    Channel(
        name="y",
        causality=Causality.OUTPUT,
        type=ValueType.REAL,
        unit="m/s",
        description="gain * u",
    ),
    Channel(
        name="x",
        causality=Causality.OUTPUT,
        type=ValueType.REAL,
        unit="m",
        description="the integral of y",
    ),
)
"""Every channel: the SSD's connectors name them (same name, kind, type and unit)."""


class @CLASS@(Participant):
    """One run at a time: initialize, do_step..., terminate."""

    def __init__(self) -> None:
        self.values: dict[str, Value] = {}
        self.x = 0.0

    async def describe(self) -> Description:
        return Description(name="@NAME@", channels=CHANNELS)

    async def initialize(self, setup: RunSetup) -> Values:
        """The start values, then the SSD's parameters and input start values."""
        self.values = {c.name: c.start for c in CHANNELS if c.start is not None}
        self.values.update(setup.parameters)
        self.values.update(setup.inputs)
        self.x = float(self.values["x0"])
        return self.outputs()

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        """Advance from time to time + step; return the outputs at time + step."""
        self.values.update(inputs)
        self.x += self.y() * step
        return self.outputs()

    async def terminate(self, reason: str = "") -> None:
        self.values = {}

    def y(self) -> float:
        return float(self.values["gain"]) * float(self.values["u"])

    def outputs(self) -> Values:
        return {"y": self.y(), "x": self.x}


if __name__ == "__main__":
    serve_main(@CLASS@(), port=@PORT@, description=__doc__)
'''

INTEGRATOR_SSD = """\
<?xml version="1.0" encoding="UTF-8"?>
<!--
  @NAME@ alone (written by `coupler new participant @NAME@`): gain 2, input u held at 0.5,
  so y = 1 m/s and x grows by 0.1 m per step of 0.1 s until the stop time, 1 s.
  @HOST_VARIABLE@ and @PORT_VARIABLE@ move the participant (default 127.0.0.1:@PORT@).
-->
<ssd:SystemStructureDescription version="1.0" name="@NAME@"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues">
  <ssd:System name="@NAME@">
    <ssd:Elements>
      <ssd:Component name="@NAME@" type="application/x-coupler-grpc"
          source="grpc://${@HOST_VARIABLE@:-127.0.0.1}:${@PORT_VARIABLE@:-@PORT@}">
        <ssd:Connectors>
          <ssd:Connector name="gain" kind="parameter"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="x0" kind="parameter"><ssc:Real unit="m"/></ssd:Connector>
          <ssd:Connector name="u" kind="input"><ssc:Real unit="m/s"/></ssd:Connector>
          <ssd:Connector name="y" kind="output"><ssc:Real unit="m/s"/></ssd:Connector>
          <ssd:Connector name="x" kind="output"><ssc:Real unit="m"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="@NAME@">
                <ssv:Parameters>
                  <ssv:Parameter name="gain"><ssv:Real value="2.0"/></ssv:Parameter>
                  <ssv:Parameter name="u"><ssv:Real value="0.5"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <!-- every unit a connector names -->
  <ssd:Units>
    <ssc:Unit name="m"><ssc:BaseUnit m="1"/></ssc:Unit>
    <ssc:Unit name="m/s"><ssc:BaseUnit m="1" s="-1"/></ssc:Unit>
  </ssd:Units>
  <!-- SSP has no step size: OpenMCx's task annotation carries it (or coupler run step H) -->
  <ssd:DefaultExperiment startTime="0.0" stopTime="1.0">
    <ssd:Annotations>
      <ssc:Annotation type="com.avl.model.connect.ssp.task">
        <mc:Task xmlns:mc="com.avl.model.connect.ssp.task" stepType="parallel_single_thread"
            deltaTime="0.1"/>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""

INTEGRATOR_EDIT = """\
1. `CHANNELS` in `participant.py`: rename, add or remove channels (name, causality: parameter,
   input or output; type; unit; start value for parameters and inputs).
2. The step, `do_step`: compute every output at `time + step` from the inputs (held over the
   step) and your state; `initialize` sets the state from `setup.parameters` and returns every
   output at the start time. `coupler.step_end(time, step)` is the step's end on the run's
   exact time grid, should an output carry a time.
3. `@NAME@.ssd`: one `<ssd:Connector>` per channel the scenario connects or binds (same name,
   kind, type and unit), every unit a connector names in `<ssd:Units>`, the parameter values
   in `<ssv:Parameters>`, the step (`deltaTime`) and stop time in `<ssd:DefaultExperiment>`.
4. Into a bigger scenario: copy the `<ssd:Component>` into its SSD, connect it, and copy the
   `[[service]]` of `fleet.toml` into its fleet file.
"""

MINIMAL_PROGRAM = '''\
"""@NAME@: a Coupler participant.

Written by `coupler new participant @NAME@ --template minimal`: one parameter, one input, one
output; per step from t to t + h, with u held over the step:

    y = k * u

Serve it with `python participant.py --port @PORT@` (`--help`: every option, `--socket PATH`
as `coupler fleet` gives it, TLS, ...); `coupler run @NAME@.ssd` drives it. README.md says what
to edit; docs/participants.md explains every part.
"""

from __future__ import annotations

from collections.abc import Mapping

from coupler import (
    Causality,
    Channel,
    Description,
    Participant,
    RunSetup,
    Value,
    Values,
    ValueType,
    serve_main,
)

CHANNELS = (
    Channel(name="k", causality=Causality.PARAMETER, type=ValueType.REAL, start=1.0),
    Channel(name="u", causality=Causality.INPUT, type=ValueType.REAL, start=0.0),
    Channel(name="y", causality=Causality.OUTPUT, type=ValueType.REAL, description="k * u"),
)
"""Every channel: the SSD's connectors name them (same name, kind and type)."""


class @CLASS@(Participant):
    """One run at a time: initialize, do_step..., terminate."""

    def __init__(self) -> None:
        self.k = 1.0
        self.u = 0.0

    async def describe(self) -> Description:
        return Description(name="@NAME@", channels=CHANNELS)

    async def initialize(self, setup: RunSetup) -> Values:
        """The parameter and the input's start value; every output at the start time."""
        self.k = float(setup.parameters.get("k", 1.0))
        self.u = float(setup.inputs.get("u", 0.0))
        return {"y": self.k * self.u}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        """Advance from time to time + step (inputs: those that changed); the outputs at
        time + step."""
        self.u = float(inputs.get("u", self.u))
        return {"y": self.k * self.u}

    async def terminate(self, reason: str = "") -> None:
        pass


if __name__ == "__main__":
    serve_main(@CLASS@(), port=@PORT@, description=__doc__)
'''

MINIMAL_SSD = """\
<?xml version="1.0" encoding="UTF-8"?>
<!--
  @NAME@ alone (written by `coupler new participant @NAME@`, minimal template): k = 2 and the
  input u held at 0.5, so y = 1 at every step of 0.1 s until the stop time, 1 s.
  @HOST_VARIABLE@ and @PORT_VARIABLE@ move the participant (default 127.0.0.1:@PORT@).
-->
<ssd:SystemStructureDescription version="1.0" name="@NAME@"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues">
  <ssd:System name="@NAME@">
    <ssd:Elements>
      <ssd:Component name="@NAME@" type="application/x-coupler-grpc"
          source="grpc://${@HOST_VARIABLE@:-127.0.0.1}:${@PORT_VARIABLE@:-@PORT@}">
        <ssd:Connectors>
          <ssd:Connector name="k" kind="parameter"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="@NAME@">
                <ssv:Parameters>
                  <ssv:Parameter name="k"><ssv:Real value="2.0"/></ssv:Parameter>
                  <ssv:Parameter name="u"><ssv:Real value="0.5"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <!-- SSP has no step size: OpenMCx's task annotation carries it (or coupler run step H) -->
  <ssd:DefaultExperiment startTime="0.0" stopTime="1.0">
    <ssd:Annotations>
      <ssc:Annotation type="com.avl.model.connect.ssp.task">
        <mc:Task xmlns:mc="com.avl.model.connect.ssp.task" stepType="parallel_single_thread"
            deltaTime="0.1"/>
      </ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"""

MINIMAL_EDIT = """\
1. `CHANNELS` in `participant.py`: rename `k`, `u` and `y`, give them units (`unit="m/s"`),
   add more (a channel has a name, a causality: parameter, input or output, a type and, for
   parameters and inputs, a start value).
2. `initialize`: read your parameters from `setup.parameters` and the inputs' start values
   from `setup.inputs` (both keyed by channel name), return every output at the start time.
3. `do_step`: `inputs` holds the inputs that changed; compute every output at `time + step`.
   `coupler.step_end(time, step)` is that time on the run's exact grid, should an output
   carry a time.
4. `@NAME@.ssd`: one `<ssd:Connector>` per channel, with the same name, kind, type (and unit:
   then declare it in `<ssd:Units>`, see the integrator template); the parameter values in
   `<ssv:Parameters>`; the step (`deltaTime`) and stop time in `<ssd:DefaultExperiment>`.
5. Into a bigger scenario: copy the `<ssd:Component>` into its SSD, connect it, and copy the
   `[[service]]` of `fleet.toml` into its fleet file.
"""

FLEET = """\
# @NAME@ in a fleet (written by `coupler new participant @NAME@`). From this folder,
#     coupler fleet fleet.toml --exit
# starts participant.py, waits until it serves, runs @NAME@.ssd and stops it. The fleet serves
# it on a unix socket (it adds --socket PATH to the command; serve_main takes it) and steps it
# over the step socket beside it; `coupler fleet --tcp` keeps it on its port. Every key:
# docs/fleet.md.
[scenario]
ssp = "@NAME@.ssd"
out = "results"                     # each run: a new folder in it, results/latest the newest

[[service]]
name = "@NAME@"
command = ["python", "participant.py", "--port", "${@PORT_VARIABLE@:-@PORT@}"]
health = "grpc://127.0.0.1:${@PORT_VARIABLE@:-@PORT@}"
"""

README = """\
# @NAME@

A Coupler participant written by `coupler new participant @NAME@`: `participant.py` is the
program (its channels, its step, `serve_main`), `@NAME@.ssd` a scenario that runs it and
`fleet.toml` a fleet that starts the one and runs the other. Run them from this folder, with the
Python environment Coupler is installed in (in a Coupler checkout after `make setup`:
`../.venv/bin/python` and `../.venv/bin/coupler` when this folder is at its top):

    python participant.py --port @PORT@ &
    coupler run @NAME@.ssd --out results
    kill %1

or, the program started, checked and stopped for you:

    coupler fleet fleet.toml --exit

`results/results.csv` (`results/latest/` from the fleet) then holds the outputs at every step.
`@PORT_VARIABLE@=PORT` (and `@HOST_VARIABLE@`) moves the participant the SSD reaches;
`python participant.py --help` lists every option (`--socket`, TLS, ...).

## What to edit

@EDIT@
docs/participants.md explains every part; docs/fleet.md the fleet file.
"""

TEMPLATES = {
    "integrator": Template(
        summary="y = gain * u [m/s] and x, its integral [m]",
        program=INTEGRATOR_PROGRAM,
        ssd=INTEGRATOR_SSD,
        edit=INTEGRATOR_EDIT,
    ),
    "minimal": Template(
        summary="one parameter k, one input u, one output y = k * u, no units",
        program=MINIMAL_PROGRAM,
        ssd=MINIMAL_SSD,
        edit=MINIMAL_EDIT,
    ),
}
"""What ``--template`` may name, the default first."""
