"""One SSD, every deployment: the address variables each engine gives the orchestrator
(docs/deployment.md, "Addresses") turn scenarios/railway/SystemStructure.ssd's sources into
the participants that deployment runs, with TLS where the deployment has it.

    local fleet  -> grpc://127.0.0.1:5006x        (no variables: the SSD's defaults)
    compose      -> grpc://<service>:5006x         (compose.yaml)
    compose+TLS  -> grpcs://<service>:5006x        (compose.yaml + compose.tls.yaml; Swarm too)
    Kubernetes   -> grpcs://<Service>:5006x        (deploy/k8s/railway ConfigMap)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from coupler_orchestrator.ssp import load_ssp

ROOT = Path(__file__).resolve().parents[2]
SSD = ROOT / "scenarios" / "railway" / "SystemStructure.ssd"


def sources(env: dict[str, str]) -> dict[str, str]:
    scenario = load_ssp(SSD, env=env)
    return {c.name: c.source for c in scenario.components if c.name != "Driver"}


def compose_env(*files: str) -> tuple[dict[str, str], set[str]]:
    """The orchestrator's environment and the service names, merged as compose merges them."""
    env: dict[str, str] = {}
    services: set[str] = set()
    for name in files:
        config: dict[str, Any] = yaml.safe_load((ROOT / name).read_text())
        services |= set(config["services"])
        env |= config["services"].get("orchestrator", {}).get("environment", {})
    return {k: v for k, v in env.items() if k.endswith(("_SCHEME", "_HOST", "_PORT"))}, services


def test_the_local_fleet_uses_the_defaults() -> None:
    assert sources({}) == {
        "OpenRails": "grpc://127.0.0.1:50061",
        "TrackBalises": "grpc://127.0.0.1:50062",
        "Map": "grpc://127.0.0.1:50071",
    }


def test_compose_names_its_services_plaintext_then_over_tls() -> None:
    env, services = compose_env("compose.yaml")
    plain = sources(env)
    assert plain == {
        "OpenRails": "grpc://openrails-bridge:50061",
        "TrackBalises": "grpc://balise-fmu:50062",
        "Map": "grpc://mapserver:50071",
    }
    env, tls_services = compose_env("compose.yaml", "compose.tls.yaml", "compose.swarm.yaml")
    assert tls_services == services
    assert sources(env) == {k: v.replace("grpc://", "grpcs://") for k, v in plain.items()}
    for source in plain.values():
        assert source.split("//")[1].split(":")[0] in services


def test_kubernetes_names_its_services_over_tls() -> None:
    kustomization = yaml.safe_load((ROOT / "deploy/k8s/railway/kustomization.yaml").read_text())
    (config,) = [c for c in kustomization["configMapGenerator"] if c["name"] == "coupler-scenario"]
    env = dict(item.split("=", 1) for item in config["literals"])
    assert sources(env) == {
        "OpenRails": "grpcs://openrails-bridge:50061",
        "TrackBalises": "grpcs://balise-fmu:50062",
        "Map": "grpcs://mapserver:50071",
    }
