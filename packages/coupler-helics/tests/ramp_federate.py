"""A HELICS federate written with the HELICS Python API alone (no Coupler): the other side of
the test federation.

    python ramp_federate.py BROKER_PORT STEPS STEP SLOPE OUT.json [--unit U] [--name N]
                            [--delay S]

Publishes ``ramp`` (unit ``--unit``, default m/s) = SLOPE * t while the federation initializes
(t = 0) and at every time it is granted (STEP apart), subscribes to ``coupler/y`` and writes
every (granted time, value received) to OUT.json when it leaves.
"""

from __future__ import annotations

import argparse
import json
import time

import helics as h


def main() -> None:
    parser = argparse.ArgumentParser()
    for name in ("port", "steps", "step", "slope", "out"):
        parser.add_argument(name)
    parser.add_argument("--unit", default="m/s")
    parser.add_argument("--name", default="ramp")
    parser.add_argument("--delay", type=float, default=0.0, help="seconds to wait each step")
    args = parser.parse_args()
    step, slope = float(args.step), float(args.slope)
    info = h.helicsCreateFederateInfo()
    h.helicsFederateInfoSetCoreTypeFromString(info, "tcp_ss")
    h.helicsFederateInfoSetCoreInitString(
        info,
        f"--federates=1 --broker_address=127.0.0.1 --brokerport={args.port} "
        "--local_interface=127.0.0.1 --tick=500ms",
    )
    h.helicsFederateInfoSetTimeProperty(info, h.HELICS_PROPERTY_TIME_PERIOD, step)
    federate = h.helicsCreateValueFederate(args.name, info)
    ramp = h.helicsFederateRegisterGlobalTypePublication(federate, "ramp", "double", args.unit)
    y = h.helicsFederateRegisterSubscription(federate, "coupler/y", "")
    h.helicsInputSetDefaultDouble(y, -1.0)
    received: list[tuple[float, float]] = []
    try:
        h.helicsFederateEnterInitializingMode(federate)
        h.helicsPublicationPublishDouble(ramp, 0.0)
        h.helicsFederateEnterExecutingMode(federate)
        received.append((0.0, h.helicsInputGetDouble(y)))
        for k in range(1, int(args.steps) + 1):
            granted = h.helicsFederateRequestTime(federate, k * step)
            h.helicsPublicationPublishDouble(ramp, slope * granted)
            received.append((granted, h.helicsInputGetDouble(y)))
            time.sleep(args.delay)
    finally:
        with open(args.out, "w") as out:
            json.dump(received, out)
        h.helicsFederateDisconnect(federate)
        h.helicsFederateFree(federate)
        h.helicsCloseLibrary()


if __name__ == "__main__":
    main()
