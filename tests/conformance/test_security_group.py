"""The battery's security group against our own secured emulators: one started with `--security DIR`
(certificates, and certificates with a pre-shared key), one configured over the network from factory
default (which the group also checks in its factory state, with --allow-writes: a session begun,
kicked and aborted), and `cipstack conform --security` against `cipstack adapter --security DIR`."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

pytest.importorskip("cryptography", reason="the security extra (cryptography) is not installed")

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cli import main
from cipstack.conformance import CHECKS, Verdict, run
from cipstack.scanner import SyncScanner
from cipstack.security.push import configure
from tests.ports import free_port
from tests.security_peers import OPENSSL, needs_openssl

from .conftest import AdapterStarter

SECURITY_CHECKS = {i for i, spec in CHECKS.items() if spec.group == "security"}
PSK_CHECKS = {i for i in SECURITY_CHECKS if i.startswith("security.psk.")}


@pytest.fixture(scope="module")
def psk_lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder of `cipstack security init --psk`: certificates and a pre-shared key."""
    from cipstack.security.provisioning import init

    folder = tmp_path_factory.mktemp("security") / "psk-lab"
    init(folder, psk=True)
    return folder


def _expected(folder: Path) -> dict[str, str]:
    """Every check passes; those of the pre-shared key do not apply to a folder without one."""
    keyed = (folder / "psk.txt").exists()
    return {i: "pass" if keyed or i not in PSK_CHECKS else "n/a" for i in SECURITY_CHECKS}

def _verdicts(report: object) -> dict[str, str]:
    return {o.id: o.verdict.value for o in report}  # type: ignore[attr-defined]


@pytest.mark.parametrize("folder_name", ["lab", "psk_lab"])
async def test_the_group_passes_against_a_device_started_with_credentials(folder_name: str,
                                                                          request: pytest.FixtureRequest) -> None:
    lab: Path = request.getfixturevalue(folder_name)
    settings = AdapterSettings(port=0, io_port=0, security=lab, security_port=free_port())
    async with Adapter(settings) as adapter:
        report = await asyncio.to_thread(run, "127.0.0.1", adapter.port, groups="security", security=lab,
                                         security_port=settings.security_port, timeout=3.0)
    assert _verdicts(report) == _expected(lab), {o.id: o.observed for o in report if o.verdict is not Verdict.PASS}
    if lab.name == "lab":
        skipped = next(o for o in report if o.id == "security.psk.handshake")
        assert skipped.observed == (f"no psk.txt in {lab} (`cipstack security init --psk` writes one): the device's "
                                    "keys are not known")
    else:
        unknown = next(o for o in report if o.id == "security.psk.unknown_identity")
        assert "unknown to the device (alert: unknown PSK identity)" in unknown.observed


async def test_the_group_passes_before_and_after_configuration_over_the_wire(lab: Path) -> None:
    settings = AdapterSettings(port=0, io_port=0, security_objects=True, security_port=free_port())
    async with Adapter(settings) as adapter:
        # Factory default: no TLS yet; the objects and the session (with --allow-writes) pass.
        before = await asyncio.to_thread(run, "127.0.0.1", adapter.port, groups="security", security=lab,
                                         security_port=settings.security_port, timeout=3.0, allow_writes=True)
        objects = {"security.objects.attributes", "security.objects.psk_unreadable", "security.session.outside",
                   "security.session.begin"}
        assert {k: v for k, v in _verdicts(before).items() if k in objects} == dict.fromkeys(objects, "pass")
        begin = next(o for o in before if o.id == "security.session.begin")
        assert begin.observed == "after Abort_Config the state reads 00"

        def push() -> None:
            with SyncScanner(f"127.0.0.1:{adapter.port}", identify=False) as plain:
                def request(service: int, class_id: int, instance: int, attribute: int | None,
                            data: bytes) -> tuple[int, tuple[int, ...], bytes]:
                    reply = plain.request(service, class_id, instance, attribute, data, check=False)
                    return reply.general_status, reply.extended_status, reply.data
                configure(request, lab, allowed_suites=(0xC02B,))
        await asyncio.to_thread(push)
        assert adapter.secure is not None
        for _ in range(1000):
            if adapter.secure.reloads:
                break
            await asyncio.sleep(0.01)
        after = await asyncio.to_thread(run, "127.0.0.1", adapter.port, groups="security", security=lab,
                                        security_port=settings.security_port, timeout=3.0)
    assert _verdicts(after) == _expected(lab), {o.id: o.observed for o in after if o.verdict is not Verdict.PASS}
    disallowed = next(o for o in after if o.id == "security.tls.disallowed_suite")
    assert disallowed.observed == "refused: 0xC023, 0xC02C, 0xC009, 0xCCA9"


def test_conform_security_on_the_command_line(psk_lab: Path, adapter_with: AdapterStarter,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """`cipstack conform --security` against `cipstack adapter --security DIR` of a folder with a key:
    the TLS, DTLS and PSK checks all pass."""
    port = free_port()
    peer = adapter_with("--security", str(psk_lab), "--security-port", str(port))
    code = main(["conform", f"{peer.host}:{peer.port}", "--only", "security", "--security", str(psk_lab),
                 "--security-port", str(port), "--json"])
    report = json.loads(capsys.readouterr().out)
    assert {o["id"]: o["verdict"] for o in report["checks"]} == dict.fromkeys(SECURITY_CHECKS, "pass"), report
    assert code == 0
    assert report["options"]["security"] == str(psk_lab)


def test_without_credentials_the_group_is_left_out_or_not_run() -> None:
    from cipstack.conformance import parse_groups

    assert "security" in parse_groups(None)
    from tests.conformance.fake_target import FakeTarget

    with FakeTarget() as target:
        report = run(target.host, target.port, groups="security", timeout=2.0)
    assert {o.verdict for o in report} == {Verdict.NOT_RUN}
    assert all("needs --security DIR" in o.observed for o in report)


async def test_a_folder_of_a_key_alone_runs_the_objects_checks_not_the_tls_ones(tmp_path: Path) -> None:
    from cipstack.security.provisioning import init

    folder = tmp_path / "psk"
    init(folder, certificates=False, psk=True)
    settings = AdapterSettings(port=0, io_port=0, security=folder, security_port=free_port())
    async with Adapter(settings) as adapter:
        report = await asyncio.to_thread(run, "127.0.0.1", adapter.port, groups="security", security=folder,
                                         security_port=settings.security_port, timeout=3.0)
    verdicts = _verdicts(report)
    tls = {i for i in SECURITY_CHECKS if i.startswith(("security.tls.", "security.dtls."))}
    assert {i: verdicts[i] for i in tls} == dict.fromkeys(tls, "not run")
    assert all(verdicts[i] == "pass" for i in SECURITY_CHECKS - tls), verdicts
    allowed = next(o for o in report if o.id == "security.tls.allowed_suite")
    assert allowed.observed == (f"needs ca.pem, client.pem, client.key in {folder} (the TLS checks handshake "
                                "with certificates, not with a pre-shared key)")


def test_a_folder_that_does_not_load_leaves_the_dtls_and_key_checks_not_run(tmp_path: Path) -> None:
    """The folder is the battery's: a psk.txt that does not read is named, and no check of the device fails
    for it."""
    import shutil

    from tests.conformance.fake_target import FakeTarget

    with FakeTarget(security=True) as target:
        assert target.security is not None
        folder = tmp_path / "broken"
        shutil.copytree(target.security.folder, folder)
        (folder / "psk.txt").write_text("no colon here\n")
        report = run(target.host, target.port, groups="security", security=folder,
                     security_port=target.security.port, timeout=2.0)
    verdicts = {o.id: (o.verdict.value, o.observed) for o in report}
    loaded = {i for i in SECURITY_CHECKS if i.startswith(("security.dtls.", "security.psk."))}
    assert {i: verdicts[i] for i in loaded} == dict.fromkeys(loaded, ("not run", f"{folder / 'psk.txt'}: not one "
                                                                                 "line IDENTITY:HEX"))
    assert all(verdicts[i][0] == "pass" for i in SECURITY_CHECKS - loaded), verdicts


@needs_openssl
def test_openssl_s_server_which_takes_any_psk_identity_fails_the_unknown_identity_check(psk_lab: Path) -> None:
    """A real peer: `openssl s_server -psk` serves whatever identity the client names (it only warns), and
    answers no EtherNet/IP; it listens on TCP alone, so the DTLS checks find no port there (ICMP)."""
    import subprocess

    from tests.conformance.fake_target import FakeTarget
    from tests.waiting import stop_process, wait_listening

    assert OPENSSL is not None
    identity, _, key = (psk_lab / "psk.txt").read_text().strip().partition(":")
    port = free_port()
    server = subprocess.Popen([OPENSSL, "s_server", "-tls1_2", "-accept", f"127.0.0.1:{port}", "-quiet", "-nocert",
                               "-psk", key, "-psk_identity", identity, "-cipher", "PSK"],
                              stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_listening(server, port, "s_server to listen")
        assert server.poll() is None
        with FakeTarget() as target:   # the plain port, whose objects say nothing of the suites
            report = run(target.host, target.port, groups="security", security=psk_lab, security_port=port,
                         timeout=2.0)
    finally:
        stop_process(server)
    verdicts = {o.id: (o.verdict.value, o.observed) for o in report}
    assert verdicts["security.psk.unknown_identity"][0] == "fail"
    assert verdicts["security.psk.unknown_identity"][1].startswith("identity 'cipstack-conform-")
    assert verdicts["security.psk.handshake"] == ("fail", "no reply to RegisterSession over TLS within 2 s")
    for dtls in ("security.dtls.handshake", "security.dtls.plaintext"):
        verdict, observed = verdicts[dtls]
        assert verdict == "n/a" and observed.startswith("no DTLS port: ")
        assert observed.endswith(f"DTLS with 127.0.0.1:{port}: nothing listens there (ICMP port unreachable)")
