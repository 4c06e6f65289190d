"""What a Kubernetes cluster would make of deploy/'s rendered objects, as Pods for ``podman kube play``
(tests/test_podman.py): a StatefulSet's pods, one per ordinal with its name as host name, each with the
claims of its ``volumeClaimTemplates`` named as the controller names them (``TEMPLATE-NAME-ORDINAL``:
``kube play`` makes a named podman volume of each, which outlives the pod as a claim does); a
Deployment's pod; a ConfigMap given to ``kube play --configmap``. Secret volumes become host directories
of the secret's files, readable by the pods' user (podman 4.3's ``kube play`` mounts no Secret object).

The containers' ``ports`` are left out (a probe that names one gets its number): podman 4.3's ``kube
play`` publishes a container port without a host port on the host's same port, which the pods of one
StatefulSet would each take (Kubernetes publishes nothing for them).

The pods restart on failure (``OnFailure``) where Kubernetes restarts them always: podman 4.3's ``kube
play`` applies a pod's restart policy to its init containers too, so that under ``Always`` it runs the
init container again as soon as it has ended, and the pod never starts."""

from __future__ import annotations

import base64
import copy
import os
from pathlib import Path
from typing import Any

#: See the module docstring.
RESTART_POLICY = "OnFailure"


def _unpublished(spec: dict[str, Any]) -> dict[str, Any]:
    """``spec`` (a pod's) with no container port, and every probe's named port as its number."""
    for container in [*spec.get("initContainers", []), *spec.get("containers", [])]:
        numbers = {port["name"]: port["containerPort"] for port in container.pop("ports", []) if "name" in port}
        for probe in ("startupProbe", "readinessProbe", "livenessProbe"):
            for kind in ("tcpSocket", "httpGet"):
                action = container.get(probe, {}).get(kind)
                if action is not None and isinstance(action.get("port"), str):
                    action["port"] = numbers[action["port"]]
    return spec


def statefulset_pods(statefulset: dict[str, Any]) -> list[dict[str, Any]]:
    """The pods of ``statefulset``, ``NAME-0`` to ``NAME-(replicas - 1)``, each named and host-named so."""
    template = statefulset["spec"]["template"]
    name = statefulset["metadata"]["name"]
    pods = []
    for ordinal in range(statefulset["spec"]["replicas"]):
        spec = _unpublished(copy.deepcopy(template["spec"]))
        spec["hostname"] = f"{name}-{ordinal}"
        spec.setdefault("volumes", []).extend(
            {"name": claim["metadata"]["name"],
             "persistentVolumeClaim": {"claimName": claim_name(statefulset, claim, ordinal)}}
            for claim in statefulset["spec"].get("volumeClaimTemplates", []))
        spec["restartPolicy"] = RESTART_POLICY
        pods.append({"apiVersion": "v1", "kind": "Pod",
                     "metadata": {"name": f"{name}-{ordinal}", "labels": dict(template["metadata"].get("labels", {})),
                                  "annotations": dict(template["metadata"].get("annotations", {}))},
                     "spec": spec})
    return pods


def claim_name(statefulset: dict[str, Any], claim: dict[str, Any], ordinal: int) -> str:
    """The claim the StatefulSet controller makes of ``claim`` (a volume claim template) for pod ``ordinal``."""
    return f"{claim['metadata']['name']}-{statefulset['metadata']['name']}-{ordinal}"


def deployment_pod(deployment: dict[str, Any]) -> dict[str, Any]:
    template = deployment["spec"]["template"]
    spec = _unpublished(copy.deepcopy(template["spec"]))
    spec["restartPolicy"] = RESTART_POLICY
    return {"apiVersion": "v1", "kind": "Pod",
            "metadata": {"name": deployment["metadata"]["name"], "labels": dict(template["metadata"]["labels"])},
            "spec": spec}


def secrets_as_directories(pod: dict[str, Any], secrets: dict[str, dict[str, Any]], root: Path) -> None:
    """Each secret volume of ``pod`` as a host directory under ``root`` holding the secret's files."""
    for volume in pod["spec"].get("volumes", []):
        if "secret" not in volume:
            continue
        name = volume.pop("secret")["secretName"]
        directory = root / name
        directory.mkdir(parents=True, exist_ok=True)
        os.chmod(directory, 0o755)
        for key, value in secrets[name].get("data", {}).items():
            path = directory / key
            path.write_bytes(base64.b64decode(value))
            os.chmod(path, 0o444)
        volume["hostPath"] = {"path": str(directory), "type": "Directory"}
