#!/usr/bin/env bash
# The Kubernetes check (CI, `make k8s-check`): render the kustomizations in deploy/k8s (the base
# and the railway overlay, with a development PKI for its Secrets) and validate every object
# against the Kubernetes API schema of the versions named below (kubernetes-validate, strict:
# unknown fields are errors). No cluster runs here: nothing is applied, scheduled or probed;
# docs/deployment.md says what is and is not verified.
#
# Environment: K8S_CHECK_OUT (default build/k8s-check), K8S_VERSIONS (default "1.30.0 1.37.0":
# the oldest and newest Kubernetes minor versions checked).
set -euo pipefail
cd "$(dirname "$0")/.."

OUT=${K8S_CHECK_OUT:-build/k8s-check}
VERSIONS=${K8S_VERSIONS:-1.30.0 1.37.0}
UV=$(command -v uv || echo .venv-uv/bin/uv)
say() { echo "k8s-check: $*"; }

render() {  # kustomization folder -> YAML on stdout
  if command -v kubectl >/dev/null; then
    kubectl kustomize "$1"
  elif command -v kustomize >/dev/null; then
    kustomize build "$1"
  else
    say "FAILED: neither kubectl nor kustomize is on PATH (either renders the manifests)" >&2
    return 1
  fi
}

rm -rf "$OUT"
mkdir -p "$OUT"
cp -r deploy/k8s "$OUT/k8s"
rm -rf "$OUT/k8s/railway/pki"
# The Secrets' files, as a user makes them (docs/deployment.md): a throwaway CA here.
"$UV" run --frozen python -m coupler_dev.devcerts "$OUT/k8s/railway/pki" --name openrails-bridge \
  --name balise-fmu --name mapserver >/dev/null
for kustomization in base railway; do
  render "$OUT/k8s/$kustomization" >"$OUT/$kustomization.yaml"
  objects=$(grep -c '^kind:' "$OUT/$kustomization.yaml")
  for version in $VERSIONS; do
    "$UV" run --frozen kubernetes-validate --strict --quiet -k "$version" "$OUT/$kustomization.yaml"
    say "deploy/k8s/$kustomization: $objects objects valid against Kubernetes $version (strict)"
  done
done
say "rendered manifests in $OUT/{base,railway}.yaml; not applied to any cluster"
say "PASSED"
