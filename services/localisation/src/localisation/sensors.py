"""The onboard sensor models as participants: ``OdometerParticipant`` (``localisation.odometer``)
and ``TransmissionParticipant`` (``localisation.transmission``). They are the test bench's, not
the system under test's: they turn the simulator's truth into what the train's sensors deliver,
and pass the truth on for the scorer and the map.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from coupler.channels import Capabilities, Causality, Channel, Description, RunSetup, Value
from coupler.channels import ValueType as T
from coupler.errors import ChannelValueError
from coupler.participant import Participant, Values
from localisation.odometer import Measurement, Odometer, OdometerErrors
from localisation.transmission import BaliseFaults, Transmission

_IN, _OUT, _PAR = Causality.INPUT, Causality.OUTPUT, Causality.PARAMETER


def _channel(
    name: str, causality: Causality, type: T, start: Value | None, unit: str = "", **more: Any
) -> Channel:
    return Channel(name=name, causality=causality, type=type, start=start, unit=unit, **more)


ODOMETER_CHANNELS = (
    _channel("distance", _IN, T.REAL, 0.0, "m", description="True distance travelled"),
    _channel("speed", _IN, T.REAL, 0.0, "m/s", description="True speed"),
    _channel("acceleration", _IN, T.REAL, 0.0, "m/s2",
             description="True acceleration (mean over the simulator's last step)"),
    _channel("wheelslip", _IN, T.BOOLEAN, False,
             description="The simulator says the wheels slip"),
    _channel("wheelskid", _IN, T.BOOLEAN, False,
             description="The simulator says the wheels slide"),
    _channel("front_offset", _PAR, T.REAL, 0.0, "m",
             description="Front end along the line when the train has travelled 0 m (truth)"),
    _channel("wheel_diameter", _PAR, T.REAL, 0.77, "m", description="True wheel diameter"),
    _channel("diameter_error", _PAR, T.REAL, 0.0,
             description="Relative error of the assumed diameter: 0.01 reads 1 % long"),
    _channel("pulses_per_revolution", _PAR, T.INTEGER, 200,
             description="Wheel sensor pulses per turn"),
    _channel("adhesion", _PAR, T.REAL, 0.3,
             description="Adhesion the rail gives: dry 0.3, wet 0.1, leaves 0.04"),
    _channel("traction_mass_fraction", _PAR, T.REAL, 0.67,
             description="Share of the weight on driven axles"),
    _channel("braked_mass_fraction", _PAR, T.REAL, 1.0,
             description="Share of the weight on braked axles"),
    _channel("slip", _PAR, T.REAL, 0.1,
             description="Wheel over-speed while slipping, relative"),
    _channel("slide", _PAR, T.REAL, 0.1,
             description="Wheel under-speed while sliding, relative (1: locked)"),
    _channel("radar", _PAR, T.BOOLEAN, False, description="A Doppler radar is fitted"),
    _channel("radar_bias", _PAR, T.REAL, 0.0, description="Relative error of the radar"),
    _channel("radar_noise", _PAR, T.REAL, 0.05, "m/s", description="Radar noise (1 sigma)"),
    _channel("radar_min_speed", _PAR, T.REAL, 0.5, "m/s",
             description="No radar reading below this speed"),
    _channel("seed", _PAR, T.INTEGER, 0, description="Seed of the random draws"),
    _channel("distance_measured", _OUT, T.REAL, None, "m",
             description="Measured distance (whole pulses)"),
    _channel("speed_measured", _OUT, T.REAL, None, "m/s",
             description="Wheel speed (pulses over the step)"),
    _channel("radar_speed", _OUT, T.REAL, None, "m/s", description="Radar speed"),
    _channel("radar_valid", _OUT, T.BOOLEAN, None, description="The radar gives a reading"),
    _channel("adhesion_state", _OUT, T.INTEGER, None,
             description="1 slipping, 0 rolling, -1 sliding (truth)"),
    _channel("true_front", _OUT, T.REAL, None, "m",
             description="The front end's true place the measurement stands for (truth)"),
)  # fmt: skip

TRANSMISSION_CHANNELS = (
    _channel("passed_in_step", _IN, T.STRING, "",
             description="Balises passed (TrackBalises): id:group:distance;..."),
    _channel("distance", _IN, T.REAL, 0.0, "m", description="True distance travelled"),
    _channel("antenna_offset", _PAR, T.REAL, 0.0, "m",
             description="Antenna = distance + this (TrackBalises' antenna_offset)"),
    _channel("loss_probability", _PAR, T.REAL, 0.0, description="Chance a balise is lost"),
    _channel("lost_balises", _PAR, T.STRING, "", description="Balise ids lost: 1000,1001"),
    _channel("group_loss_probability", _PAR, T.REAL, 0.0,
             description="Chance a whole group is lost"),
    _channel("lost_groups", _PAR, T.STRING, "", description="Group ids lost: 100,104"),
    _channel("late_probability", _PAR, T.REAL, 0.0, description="Chance a group comes late"),
    _channel("late_groups", _PAR, T.STRING, "", description="Group ids late: 102"),
    _channel("late_delay", _PAR, T.REAL, 1.0, "s", description="How late a late group is"),
    _channel("corrupt_probability", _PAR, T.REAL, 0.0,
             description="Chance a telegram is corrupt"),
    _channel("corrupt_balises", _PAR, T.STRING, "", description="Balise ids corrupt: 1020"),
    _channel("seed", _PAR, T.INTEGER, 0, description="Seed of the fault draws"),
    _channel("telegrams", _OUT, T.STRING, None,
             description="Telegrams delivered in the step: balise_id:group_id:time;..."),
    _channel("faults", _OUT, T.STRING, None,
             description="Faults injected in the step: lost|late|corrupt:balise:group;... (truth)"),
)  # fmt: skip


def _defaults(channels: tuple[Channel, ...], causality: Causality) -> dict[str, Value]:
    return {c.name: c.start for c in channels if c.causality is causality and c.start is not None}


class OdometerParticipant(Participant):
    """The odometer sensor model; see ``localisation.odometer``."""

    async def describe(self) -> Description:
        return Description(
            name="Odometer",
            channels=ODOMETER_CHANNELS,
            capabilities=Capabilities(streaming=True, variable_step_size=True),
            implementation="coupler odometer model 0.1.0 (wheel pulses, slip/slide, radar)",
        )

    async def initialize(self, setup: RunSetup) -> Values:
        p = {**_defaults(ODOMETER_CHANNELS, _PAR), **setup.parameters}
        try:
            errors = OdometerErrors(
                wheel_diameter_m=float(p["wheel_diameter"]),
                diameter_error=float(p["diameter_error"]),
                pulses_per_revolution=int(p["pulses_per_revolution"]),
                adhesion=float(p["adhesion"]),
                traction_mass_fraction=float(p["traction_mass_fraction"]),
                braked_mass_fraction=float(p["braked_mass_fraction"]),
                slip=float(p["slip"]),
                slide=float(p["slide"]),
                radar=bool(p["radar"]),
                radar_bias=float(p["radar_bias"]),
                radar_noise_mps=float(p["radar_noise"]),
                radar_min_speed_mps=float(p["radar_min_speed"]),
                seed=int(p["seed"]),
            )
        except ValueError as exc:
            raise ChannelValueError(f"Odometer parameters: {exc}", channel="parameters") from exc
        self._front_offset = float(p["front_offset"])
        self._inputs = {**_defaults(ODOMETER_CHANNELS, _IN), **setup.inputs}
        self._odometer = Odometer(errors)
        return self._outputs(self._odometer.start(float(self._inputs["distance"])))

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self._inputs.update(inputs)
        i = self._inputs
        return self._outputs(
            self._odometer.step(
                step,
                distance_m=float(i["distance"]),
                speed_mps=float(i["speed"]),
                acceleration_mps2=float(i["acceleration"]),
                wheelslip=bool(i["wheelslip"]),
                wheelskid=bool(i["wheelskid"]),
            )
        )

    async def terminate(self, reason: str = "") -> None:
        pass

    def _outputs(self, m: Measurement) -> Values:
        return {
            "distance_measured": m.distance_m,
            "speed_measured": m.speed_mps,
            "radar_speed": m.radar_speed_mps,
            "radar_valid": m.radar_valid,
            "adhesion_state": m.adhesion_state,
            "true_front": self._front_offset + m.true_distance_m,
        }


class TransmissionParticipant(Participant):
    """The balise reader with its faults; see ``localisation.transmission``."""

    async def describe(self) -> Description:
        return Description(
            name="BaliseTransmission",
            channels=TRANSMISSION_CHANNELS,
            capabilities=Capabilities(streaming=True, variable_step_size=True),
            implementation="coupler balise transmission model 0.1.0 (loss, late, corrupt)",
        )

    async def initialize(self, setup: RunSetup) -> Values:
        p = {**_defaults(TRANSMISSION_CHANNELS, _PAR), **setup.parameters}
        try:
            faults = BaliseFaults(
                loss_probability=float(p["loss_probability"]),
                lost_balises=_ids(p, "lost_balises"),
                group_loss_probability=float(p["group_loss_probability"]),
                lost_groups=_ids(p, "lost_groups"),
                late_probability=float(p["late_probability"]),
                late_groups=_ids(p, "late_groups"),
                late_delay_s=float(p["late_delay"]),
                corrupt_probability=float(p["corrupt_probability"]),
                corrupt_balises=_ids(p, "corrupt_balises"),
                seed=int(p["seed"]),
            )
        except ValueError as exc:
            raise ChannelValueError(
                f"BaliseTransmission parameters: {exc}", channel="parameters"
            ) from exc
        self._inputs = {**_defaults(TRANSMISSION_CHANNELS, _IN), **setup.inputs}
        self._transmission = Transmission(
            faults=faults,
            antenna_offset_m=float(p["antenna_offset"]),
        )
        self._transmission.start(setup.start_time, float(self._inputs["distance"]))
        return {"telegrams": "", "faults": ""}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self._inputs.update(inputs)
        # passed_in_step lists a step's balises once: a value left from an earlier step (when
        # only changed inputs come) is not passed again
        passed = str(inputs.get("passed_in_step", ""))
        try:
            telegrams, faults = self._transmission.step(
                time,
                passed,
                float(self._inputs["distance"]),
            )
        except ValueError as exc:
            raise ChannelValueError(
                f"channel 'passed_in_step': {exc}", channel="passed_in_step"
            ) from exc
        return {"telegrams": telegrams, "faults": faults}

    async def terminate(self, reason: str = "") -> None:
        pass


def _ids(parameters: Mapping[str, Value], name: str) -> frozenset[int]:
    text = str(parameters.get(name, "") or "")
    try:
        return frozenset(int(part) for part in text.replace(";", ",").split(",") if part.strip())
    except ValueError as exc:
        raise ValueError(f"{name} {text!r} is not a list of whole numbers (1000,1001)") from exc
