"""The Kubernetes manifests (deploy/k8s), rendered by scripts/k8s-check.sh and read back.

    kustomize: base (orchestrator Job, results PVC, NetworkPolicy) + railway overlay
               (participants, ConfigMap of addresses, Secrets) --> kubernetes-validate (strict)

No cluster runs here: the schema check is the script's; this test checks what a schema cannot,
the wiring between objects (probes on the health port, Services that select their pods, the
orchestrator's addresses naming those Services, Secrets and the volume that exist, the
NetworkPolicy letting the orchestrator in and nobody else).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import kubernetes_validate
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.timeout(180)


@pytest.fixture(scope="module")
def railway(tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, Any]]:
    if shutil.which("kubectl") is None and shutil.which("kustomize") is None:
        pytest.skip("neither kubectl nor kustomize is installed: nothing renders the manifests")
    out = tmp_path_factory.mktemp("k8s")
    done = subprocess.run(
        ["bash", "scripts/k8s-check.sh"],
        cwd=ROOT,
        env={**os.environ, "K8S_CHECK_OUT": str(out)},
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "k8s-check: PASSED" in done.stdout
    return list(yaml.safe_load_all((out / "railway.yaml").read_text()))


def of_kind(objects: list[dict[str, Any]], kind: str) -> dict[str, dict[str, Any]]:
    return {o["metadata"]["name"]: o for o in objects if o["kind"] == kind}


def pod_labels(workload: dict[str, Any]) -> dict[str, str]:
    labels: dict[str, str] = workload["spec"]["template"]["metadata"]["labels"]
    return labels


def env_of(container: dict[str, Any]) -> dict[str, str]:
    return {e["name"]: e["value"] for e in container.get("env", ())}


def selects(selector: dict[str, str], labels: dict[str, str]) -> bool:
    return all(labels.get(k) == v for k, v in selector.items())


PARTICIPANTS = {  # Deployment -> (environment prefix, gRPC port)
    "openrails-bridge": ("OPENRAILS_BRIDGE_", 50061),
    "balise-fmu": ("BALISE_FMU_", 50062),
    "mapserver": ("MAPSERVER_", 50071),
}


@pytest.mark.slow
def test_participants_serve_tls_and_are_probed_on_their_health_port(
    railway: list[dict[str, Any]],
) -> None:
    deployments = of_kind(railway, "Deployment")
    secrets = of_kind(railway, "Secret")
    for name, (prefix, port) in PARTICIPANTS.items():
        pod = deployments[name]["spec"]["template"]["spec"]
        (container,) = pod["containers"]
        env = env_of(container)
        ports = {p["name"]: p["containerPort"] for p in container["ports"]}
        assert ports["grpc"] == port
        health = int(env[f"{prefix}HEALTH_PORT"])
        assert ports["health"] == health != port
        assert container["readinessProbe"]["grpc"]["port"] == health, name
        liveness = container["livenessProbe"]
        # the bridge is alive but not ready while OpenRails is down: liveness is the socket
        probed = liveness["tcpSocket"] if name == "openrails-bridge" else liveness["grpc"]
        assert probed["port"] == health, name
        # TLS files named by the environment are in mounted Secrets that exist
        mounts = {m["mountPath"]: m["name"] for m in container["volumeMounts"]}
        volumes = {v["name"]: v for v in pod["volumes"]}
        for key in ("TLS_CERT", "TLS_KEY", "TLS_CLIENT_CA", "TOKEN_FILE"):
            folder, file = env[prefix + key].rsplit("/", 1)
            secret = secrets[volumes[mounts[folder]]["secret"]["secretName"]]
            assert file in secret["data"], (name, key)
        assert "client-key.pem" not in secrets[volumes["tls"]["secret"]["secretName"]]["data"]


def test_the_orchestrator_names_the_services_and_keeps_results(
    railway: list[dict[str, Any]],
) -> None:
    (job,) = of_kind(railway, "Job").values()
    pod = job["spec"]["template"]["spec"]
    (container,) = pod["containers"]
    (config_ref,) = container["envFrom"]
    addresses = of_kind(railway, "ConfigMap")[config_ref["configMapRef"]["name"]]["data"]
    services = of_kind(railway, "Service")
    deployments = of_kind(railway, "Deployment")
    for variable in ("BRIDGE", "BALISE", "MAP"):
        assert addresses[f"{variable}_SCHEME"] == "grpcs"
        service = services[addresses[f"{variable}_HOST"]]
        assert int(addresses[f"{variable}_PORT"]) in {p["port"] for p in service["spec"]["ports"]}
        (target,) = [
            d for d in deployments.values() if selects(service["spec"]["selector"], pod_labels(d))
        ]
        assert pod_labels(target)["app.kubernetes.io/component"] == "participant"
    assert (ROOT / addresses["COUPLER_SCENARIO"]).is_file()
    assert "$(COUPLER_SCENARIO)" in container["args"]
    volumes = {v["name"]: v for v in pod["volumes"]}
    claim = volumes["results"]["persistentVolumeClaim"]["claimName"]
    assert claim in of_kind(railway, "PersistentVolumeClaim")
    assert {"mountPath": "/results", "name": "results"} in container["volumeMounts"]
    tls = of_kind(railway, "Secret")[volumes["tls"]["secret"]["secretName"]]["data"]
    assert set(tls) == {"ca.pem", "client.pem", "client-key.pem"}  # not the participants' key


def test_only_the_orchestrator_may_call_participants(railway: list[dict[str, Any]]) -> None:
    policy = of_kind(railway, "NetworkPolicy")["coupler-participants-from-orchestrator"]
    selector = policy["spec"]["podSelector"]["matchLabels"]
    (rule,) = policy["spec"]["ingress"]
    (source,) = rule["from"]
    allowed = source["podSelector"]["matchLabels"]
    assert [p["port"] for p in rule["ports"]] == ["grpc"]
    for name, deployment in of_kind(railway, "Deployment").items():
        assert selects(selector, pod_labels(deployment)) == (name in PARTICIPANTS), name
        assert not selects(allowed, pod_labels(deployment)), name
    (job,) = of_kind(railway, "Job").values()
    assert selects(allowed, pod_labels(job))


def test_the_schema_check_refuses_a_misspelt_field(railway: list[dict[str, Any]]) -> None:
    """The strict schema check is not a formality: one wrong key fails it."""
    deployment = of_kind(railway, "Deployment")["balise-fmu"]
    container = deployment["spec"]["template"]["spec"]["containers"][0]
    container["readinessProbe"]["periodSecond"] = container["readinessProbe"].pop("periodSeconds")
    with pytest.raises(kubernetes_validate.ValidationError, match="periodSecond"):
        kubernetes_validate.validate(deployment, "1.30.0", strict=True)
