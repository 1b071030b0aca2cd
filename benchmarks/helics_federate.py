"""A HELICS value federate written with the HELICS Python API alone, for `make bench`
(benchmarks/frameworks.py): the HELICS side of the framework rows.

    python benchmarks/helics_federate.py ramp BROKER_PORT STEPS STEP   # prints its steps/s
    python benchmarks/helics_federate.py echo BROKER_PORT STEPS STEP

``ramp`` publishes ``ramp`` = t and subscribes to ``coupler/y``; ``echo`` is the other side
without Coupler: it subscribes to ``ramp`` and publishes ``coupler/y`` = 4 * ramp. Both request
every multiple of STEP up to STEPS * STEP; ``ramp`` prints the steps per second of wall time
from entering executing mode to its last grant.
"""

from __future__ import annotations

import sys
import time

import helics as h


def main() -> None:
    role, port, steps, step = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
    info = h.helicsCreateFederateInfo()
    h.helicsFederateInfoSetCoreTypeFromString(info, "tcp_ss")
    h.helicsFederateInfoSetCoreInitString(
        info,
        f"--federates=1 --broker_address=127.0.0.1 --brokerport={port} "
        "--local_interface=127.0.0.1 --tick=500ms",
    )
    h.helicsFederateInfoSetFlagOption(info, h.HELICS_FLAG_UNINTERRUPTIBLE, True)
    federate = h.helicsCreateValueFederate(role, info)
    out, into = ("ramp", "coupler/y") if role == "ramp" else ("coupler/y", "ramp")
    publication = h.helicsFederateRegisterGlobalTypePublication(federate, out, "double", "")
    subscription = h.helicsFederateRegisterSubscription(federate, into, "")
    h.helicsInputSetDefaultDouble(subscription, 0.0)
    h.helicsFederateEnterExecutingMode(federate)
    began = time.perf_counter()
    for k in range(1, steps + 1):
        granted = h.helicsFederateRequestTime(federate, k * step)
        given = h.helicsInputGetDouble(subscription)
        h.helicsPublicationPublishDouble(publication, granted if role == "ramp" else 4.0 * given)
    took = time.perf_counter() - began
    h.helicsFederateDisconnect(federate)
    h.helicsFederateFree(federate)
    h.helicsCloseLibrary()
    if role == "ramp":
        print(f"{steps / took:.1f}", flush=True)


if __name__ == "__main__":
    main()
