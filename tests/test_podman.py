"""The image and the manifests, run: the Containerfile built with podman from a base made of Debian
packages (debootstrap, no public registry), deploy/'s objects rendered by ``kubectl kustomize``
(tests/podman: a plant of nine drives in three shards) and their pods run with ``podman kube play`` on
a podman bridge network inside a private network namespace, standing for the plant's layer 2
network. From another container on it: ``cipstack discover`` finds every drive once, ``cipstack io``
holds a class 1 connection to a drive of each shard, the plant view lists every device; a fleet
killed is restarted and its drives answer again.

What differs from a cluster, and why: the pods are made from the StatefulSet and the Deployment by
tests/podman_pods.py (no controller here); the headless Service's DNS records are the plant view's
``hostAliases`` (its /etc/hosts, the fleet pods' addresses); podman runs containers here only with
lowered limits and the runc runtime (``CONTAINERS_CONF`` below, the harness's, not the image's).

Marked ``podman``; needs root, podman, runc, debootstrap, iproute2, util-linux and a Debian mirror (the base image
is built once and kept as ``localhost/cipstack-base:CODENAME``), and PyPI for the wheels the image
installs (built here for the base's Python)."""

from __future__ import annotations

import base64
import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("yaml", reason="PyYAML renders the manifests (the test extra): pip install '.[test]'")

import yaml  # type: ignore[import-untyped]

from tests.podman_pods import claim_name, deployment_pod, secrets_as_directories, statefulset_pods
from tests.test_deploy import documented_secret, kubectl

pytestmark = [pytest.mark.podman, pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux only")]

ROOT = Path(__file__).resolve().parent.parent
IMAGE = "localhost/cipstack:test"
#: The plant network (tests/podman/plant.toml: the drives at .100-.108; podman gives pods .2-.62).
SUBNET, IP_RANGE, BROADCAST = "10.89.50.0/24", "10.89.50.0/26", "10.89.50.255"
DRIVES = [f"10.89.50.{100 + n}" for n in range(9)]
#: The image run alone, as an adapter (its default command): outside the range podman gives out.
ADAPTER = "10.89.50.90"
#: An ACG drive of each shard (the last shard's other two are MX2s).
ONE_PER_SHARD = ["10.89.50.100", "10.89.50.103", "10.89.50.106"]
#: podman on this kind of machine: containers start only with these limits, under runc.
CONTAINERS_CONF = """[containers]
default_ulimits = ["nofile=1024:1024", "nproc=4096:4096"]
[engine]
runtime = "runc"
"""
LIMITS = ["--ulimit", "nofile=1024:1024", "--ulimit", "nproc=4096:4096"]


def _missing() -> str | None:
    if os.geteuid() != 0:
        return "needs root (a private network namespace, podman's bridge network)"
    for tool in ("podman", "runc", "debootstrap", "ip", "nsenter", "tar"):
        if shutil.which(tool) is None and not Path(f"/usr/sbin/{tool}").exists():
            return f"needs {tool} (.ci/run installs it)"
    if not Path("/etc/debian_version").exists():
        return "builds its base image with debootstrap from the host's Debian release"
    return None


class Podman:
    """podman in the test's network namespace, with the harness's limits."""

    def __init__(self, namespace: str, conf: Path) -> None:
        self.namespace = namespace
        self.env = {**os.environ, "CONTAINERS_CONF": str(conf)}

    def __call__(self, *args: str, timeout: float = 120, check: bool = True,
                 netns: bool = True) -> subprocess.CompletedProcess[str]:
        # nsenter, not `ip netns exec`: that mounts a sysfs of its own, without the cgroup file system
        # that podman sets the pods' resource limits in.
        prefix = ["nsenter", f"--net=/run/netns/{self.namespace}"] if netns else []
        result = subprocess.run([*prefix, "podman", *args], capture_output=True, text=True, timeout=timeout,
                                env=self.env, check=False)
        if check and result.returncode != 0:
            raise AssertionError(f"podman {' '.join(args)}: exit {result.returncode}\n{result.stdout}\n{result.stderr}")
        return result

    def client(self, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
        """A command of the image in a container of its own on the plant network."""
        return self("run", "--rm", "--network", "plant", "--no-healthcheck", *LIMITS, *args, timeout=timeout)


def _os_codename() -> str:
    fields = dict(line.split("=", 1) for line in Path("/etc/os-release").read_text().splitlines() if "=" in line)
    return fields.get("VERSION_CODENAME", "").strip('"') or "bookworm"


def _mirror() -> str:
    """The host's Debian mirror (its apt sources), for debootstrap."""
    for path in [Path("/etc/apt/sources.list"), *sorted(Path("/etc/apt/sources.list.d").glob("*"))]:
        with contextlib.suppress(OSError):
            for line in path.read_text().splitlines():
                words = line.split()
                if words[:1] == ["URIs:"] and "security" not in words[1]:
                    return words[1]
                if words[:1] == ["deb"] and "security" not in line:
                    return next(w for w in words[1:] if w.startswith("http"))
    return "http://deb.debian.org/debian"


def base_image(podman: Podman, work: Path) -> str:
    """A base with python3, its venv module and iproute2, from Debian packages (debootstrap
    --variant=minbase); built once and kept."""
    codename = _os_codename()
    name = f"localhost/cipstack-base:{codename}"
    if podman("image", "exists", name, check=False, netns=False).returncode == 0:
        return name
    root = work / "rootfs"
    result = subprocess.run(["debootstrap", "--variant=minbase", "--include=python3,python3-venv,iproute2", codename,
                             str(root), _mirror()], capture_output=True, text=True, timeout=1200, check=False)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    for cache in ("var/cache/apt/archives", "var/lib/apt/lists"):
        for path in (root / cache).glob("*"):
            if path.is_file():
                path.unlink()
    with subprocess.Popen(["tar", "-C", str(root), "-c", "."], stdout=subprocess.PIPE) as tar:
        imported = subprocess.run(["podman", "import", "-", name], stdin=tar.stdout, capture_output=True, text=True,
                                  timeout=600, env=podman.env, check=False)
    assert imported.returncode == 0, imported.stderr
    shutil.rmtree(root, ignore_errors=True)
    return name


def wheels(podman: Podman, base: str, dist: Path) -> None:
    """The cipstack wheel of this checkout and its dependencies' wheels for the base's Python."""
    version = podman("run", "--rm", "--no-healthcheck", *LIMITS, base, "python3", "-c",
                     "import sys; print('%d.%d' % sys.version_info[:2])", netns=False).stdout.strip()
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "--quiet"]
    subprocess.run([*pip, "wheel", "--no-deps", "--wheel-dir", str(dist), str(ROOT)], check=True, timeout=600,
                   capture_output=True)
    (wheel,) = dist.glob("cipstack-*.whl")
    subprocess.run([*pip, "download", "--dest", str(dist), "--only-binary=:all:", "--python-version", version,
                    "--implementation", "cp", "--platform", "manylinux2014_x86_64", "--platform",
                    "manylinux_2_17_x86_64", "--platform", "manylinux_2_28_x86_64", f"{wheel}[http]"],
                   check=True, timeout=600, capture_output=True)


def build_image(podman: Podman, base: str, context: Path) -> None:
    podman("build", "--format", "docker", "--network", "none", *LIMITS, "--build-arg", f"BASE={base}",
           "--build-arg", "PIP_INDEX_URL=none", "-t", IMAGE, "-f", str(ROOT / "Containerfile"), str(context),
           timeout=900, netns=False)


#: The fleet pods' claims of saved parameters (``state-cipstack-fleet-N``), podman volumes here.
CLAIMS = [f"state-cipstack-fleet-{n}" for n in range(3)]


def pods(work: Path) -> tuple[list[dict[str, Any]], dict[str, Any], Path, str]:
    """The fleet pods, the plant view's pod, the ConfigMap's file for ``kube play``, and the token of the
    Secret made as docs/kubernetes.md says (the manifests ship none)."""
    rendered = subprocess.run([kubectl(), "kustomize", str(ROOT / "tests" / "podman")], capture_output=True,
                              text=True, check=True, timeout=120).stdout
    objects = [o for o in yaml.safe_load_all(rendered) if o]
    assert not [o for o in objects if o["kind"] == "Secret"], "the manifests ship a Secret"
    made = documented_secret()
    secrets = {made["metadata"]["name"]: made}
    token = base64.b64decode(made["data"]["token"]).decode()
    (statefulset,) = [o for o in objects if o["kind"] == "StatefulSet"]
    (deployment,) = [o for o in objects if o["kind"] == "Deployment"]
    (config,) = [o for o in objects if o["kind"] == "ConfigMap"]
    fleet = statefulset_pods(statefulset)
    assert [v["persistentVolumeClaim"]["claimName"] for pod in fleet for v in pod["spec"]["volumes"]
            if "persistentVolumeClaim" in v] == [claim_name(statefulset, statefulset["spec"]["volumeClaimTemplates"][0],
                                                            n) for n in range(3)] == CLAIMS
    view = deployment_pod(deployment)
    for pod in (*fleet, view):
        secrets_as_directories(pod, secrets, work / "secrets")
    configmap = work / "configmap.yaml"
    configmap.write_text(yaml.safe_dump(config))
    return fleet, view, configmap, token


def play(podman: Podman, pod: dict[str, Any], configmap: Path, work: Path) -> None:
    path = work / f"{pod['metadata']['name']}.yaml"
    path.write_text(yaml.safe_dump(pod))
    podman("kube", "play", "--network", "plant", "--configmap", str(configmap), str(path), timeout=180)


def wait_for_log(podman: Podman, container: str, text: str, times: int = 1, timeout: float = 90) -> None:
    deadline = time.monotonic() + timeout
    while True:
        logs = podman("logs", container, check=False)
        if (logs.stdout + logs.stderr).count(text) >= times:
            return
        assert time.monotonic() < deadline, f"{container}: no {text!r} after {timeout:g} s:\n{logs.stderr[-3000:]}"
        time.sleep(0.5)


def discovered(podman: Podman) -> list[str]:
    found = podman.client(IMAGE, "discover", "--broadcast", BROADCAST, "--timeout", "2s", "--json").stdout
    hosts = [json.loads(line)["address"].rpartition(":")[0] for line in found.splitlines() if line.strip()]
    return sorted(hosts, key=lambda host: int(host.rsplit(".", 1)[1]))   # each once: duplicates stay


def class1(podman: Podman, drive: str) -> dict[str, Any]:
    """``cipstack io`` to ``drive`` for 2 s at RPI 50 ms (what is checked is the network, not the timing of
    a machine that also builds images): its summary."""
    out = podman.client(IMAGE, "io", drive, "--output", "21", "--input", "71", "--rpi", "50ms", "--duration", "2s",
                        "--print", "summary", "--json").stdout
    summaries = [json.loads(line)["summary"] for line in out.splitlines() if '"summary"' in line]
    assert summaries, out
    return summaries[-1]  # type: ignore[no-any-return]


def plant_devices(podman: Podman, view_ip: str, token: str) -> list[dict[str, Any]]:
    request = f"urllib.request.Request('http://{view_ip}:8080/devices', headers={{'Authorization': 'Bearer {token}'}})"
    script = f"import json, urllib.request; print(json.dumps(json.load(urllib.request.urlopen({request}, timeout=10))))"
    out = podman.client("--entrypoint", "python3", IMAGE, "-c", script).stdout
    return json.loads(out)  # type: ignore[no-any-return]


def pod_ip(podman: Podman, pod: str) -> str:
    infra = podman("pod", "inspect", pod, "--format", "{{.InfraContainerID}}").stdout.strip()
    networks = json.loads(podman("inspect", infra, "--format", "{{json .NetworkSettings.Networks}}").stdout)
    return str(networks["plant"]["IPAddress"])


@pytest.fixture
def podman() -> Iterator[Podman]:
    missing = _missing()
    if missing is not None:
        pytest.skip(missing)
    work = Path(tempfile.mkdtemp(prefix="cipstack-podman-"))
    conf = work / "containers.conf"
    conf.write_text(CONTAINERS_CONF)
    namespace = f"cipstack-podman-{os.getpid()}"
    subprocess.run(["ip", "netns", "add", namespace], check=True)
    runner = Podman(namespace, conf)
    for claim in CLAIMS:   # a claim a run before this one left: its saved parameters are not this run's
        runner("volume", "rm", "--force", claim, check=False)
    try:
        subprocess.run(["nsenter", f"--net=/run/netns/{namespace}", "ip", "link", "set", "lo", "up"], check=True)
        runner("network", "create", "--subnet", SUBNET, "--ip-range", IP_RANGE, "plant")
        yield runner
    finally:
        runner("rm", "--force", "--time", "2", "cipstack-adapter", check=False)
        for pod in ("cipstack-plant", "cipstack-fleet-0", "cipstack-fleet-1", "cipstack-fleet-2"):
            runner("pod", "rm", "--force", "--time", "2", pod, check=False)
        runner("network", "rm", "--force", "plant", check=False)
        for claim in CLAIMS:
            runner("volume", "rm", "--force", claim, check=False)
        subprocess.run(["ip", "netns", "delete", namespace], check=False)
        shutil.rmtree(work, ignore_errors=True)


def test_the_image_runs_the_plant_of_the_manifests(podman: Podman) -> None:
    work = Path(podman.env["CONTAINERS_CONF"]).parent
    base = base_image(podman, work)
    wheels(podman, base, work / "context" / "dist")
    build_image(podman, base, work / "context")
    fleet, view, configmap, token = pods(work)
    assert [pod["metadata"]["name"] for pod in fleet] == ["cipstack-fleet-0", "cipstack-fleet-1", "cipstack-fleet-2"]
    for pod in fleet:
        play(podman, pod, configmap, work)
    for shard, pod in enumerate(fleet):
        wait_for_log(podman, f"{pod['metadata']['name']}-fleet", f"shard {shard}/3 of the plant")

    # Every drive of every shard once, by broadcast from another container on the plant network.
    assert discovered(podman) == DRIVES
    for drive in ONE_PER_SHARD:
        summary = class1(podman, drive)
        assert summary["received"] >= 20 and summary["lost"] == 0, (drive, summary)

    # The image's other uses: the EDS tool (a file written, then checked against a drive of the plant),
    # and the adapter, its default command, whose health check asks it who it is.
    checked = podman.client("--entrypoint", "sh", IMAGE, "-c", "cipstack eds generate --profile acg -o /tmp/eds && "
                            f"cipstack eds check --against {ONE_PER_SHARD[0]} /tmp/eds/*.eds")
    assert "1 file: 0 errors" in checked.stdout + checked.stderr, checked.stdout + checked.stderr
    podman("run", "-d", "--name", "cipstack-adapter", "--network", "plant", "--ip", ADAPTER, *LIMITS, IMAGE)
    deadline = time.monotonic() + 60
    while podman("healthcheck", "run", "cipstack-adapter", check=False).returncode != 0:
        assert time.monotonic() < deadline, podman("logs", "cipstack-adapter", check=False).stderr
        time.sleep(1)
    assert "'CENT'  vendor 259" in podman.client(IMAGE, "identity", ADAPTER).stdout
    podman("rm", "--force", "--time", "2", "cipstack-adapter")   # not a drive of the plant

    # The plant view finds the fleets by the name the headless Service would give (hostAliases here).
    view["spec"]["hostAliases"] = [{"ip": pod_ip(podman, pod["metadata"]["name"]), "hostnames": ["cipstack-fleet"]}
                                   for pod in fleet]
    play(podman, view, configmap, work)
    wait_for_log(podman, "cipstack-plant-plant", "plant view of cipstack-fleet:8080: 9 devices in 3 fleets")
    view_ip = pod_ip(podman, "cipstack-plant")
    listed = plant_devices(podman, view_ip, token)
    assert [d["address"] for d in listed] == DRIVES and not any("error" in d for d in listed), listed

    # A fleet's process killed (SIGKILL from outside: `podman kill` would be a stop by the user, which no
    # restart policy undoes): podman restarts it (the pod's restart policy), and its drives answer again.
    pid = int(podman("inspect", "cipstack-fleet-1-fleet", "--format", "{{.State.Pid}}").stdout)
    os.kill(pid, signal.SIGKILL)
    wait_for_log(podman, "cipstack-fleet-1-fleet", "shard 1/3 of the plant", times=2)
    restarts = podman("inspect", "cipstack-fleet-1-fleet", "--format", "{{.RestartCount}}").stdout.strip()
    assert int(restarts) >= 1
    assert discovered(podman) == DRIVES
    summary = class1(podman, ONE_PER_SHARD[1])
    assert summary["received"] >= 20 and summary["lost"] == 0, summary
    deadline = time.monotonic() + 30
    while any("error" in d for d in plant_devices(podman, view_ip, token)):
        assert time.monotonic() < deadline, "the plant view still shows the restarted fleet's devices as lost"
        time.sleep(1)

    # A parameter saved on a drive survives its pod: the pod deleted and made again (a reschedule), its
    # claim (a podman volume here) is mounted again and the drive reads its saved file.
    drive = ONE_PER_SHARD[1]
    assert "= 5.5 s" not in podman.client(IMAGE, "get", drive, "dEC").stdout   # factory settings, not this
    podman.client("--entrypoint", "sh", IMAGE, "-c", " && ".join((
        f"cipstack set {drive} dEC 5.5",
        # Save (register 0x03E0 from 0 to 1, ACG manual): named in CM.51, written through output assembly 121.
        f"cipstack set {drive} CM.51 992",
        f"cipstack set {drive} 0x04/121/3 0 --type UINT",
        f"cipstack set {drive} 0x04/121/3 1 --type UINT")))
    podman("pod", "rm", "--force", "--time", "2", "cipstack-fleet-1")
    assert CLAIMS[1] in podman("volume", "ls", "--format", "{{.Name}}").stdout.split()
    play(podman, fleet[1], configmap, work)
    wait_for_log(podman, "cipstack-fleet-1-fleet", "shard 1/3 of the plant")
    assert "dEC Deceleration Time = 5.5 s" in podman.client(IMAGE, "get", drive, "dEC").stdout
    # Every root file system is read-only: the fleet writes to its volumes only. As root (with no
    # capability), who owns /opt/cipstack: what refuses the write is the file system, not its modes.
    refused = podman("exec", "--user", "0", "cipstack-fleet-1-fleet", "touch", "/opt/cipstack/written", check=False)
    assert refused.returncode != 0 and "Read-only file system" in refused.stderr, refused
