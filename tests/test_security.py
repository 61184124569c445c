"""The protections of a running simbridge: tokens, the admin page, origins, TLS, rosauth."""

from __future__ import annotations

import asyncio
import datetime
import ipaddress
import json
import re
import ssl
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

import pytest
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus

from simbridge.app.guard import rosauth_mac
from tests.conftest import AppFactory, ClientRunner
from tests.helpers import TIMEOUT_FACTOR, recv_until, send_json, ws_url


ADMIN = "admin-token-for-tests"
TOKENS = {"student-one-token": "r1", "everything-token": "*"}


def fetch(url: str, context: ssl.SSLContext | None = None) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=5, context=context) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as err:
        return err.code, err.read()


async def call(ws: Any, service: str, op_id: str = "c") -> Any:
    await send_json(ws, {"op": "call_service", "service": service, "id": op_id})
    return await recv_until(ws, lambda m: m.get("op") == "service_response")


@pytest.fixture(scope="module")
def certificate(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A self-signed certificate for 127.0.0.1 and localhost, made here."""
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "localhost")])
    now = datetime.datetime.now(datetime.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(
            x509.SubjectAlternativeName(
                [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
            ),
            critical=False,
        )
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .sign(key, hashes.SHA256())
    )
    folder = tmp_path_factory.mktemp("tls")
    certfile, keyfile = folder / "cert.pem", folder / "key.pem"
    certfile.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    keyfile.write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    return certfile, keyfile


async def test_administrative_services_need_the_admin_token(make_app: AppFactory) -> None:
    app = await make_app(admin_token=ADMIN)
    async with connect(ws_url(app)) as anyone:
        reply = await call(anyone, "/reset")
        assert reply["result"] is False and "administrative" in reply["values"]
        assert (await call(anyone, "/rosapi/topics"))["result"] is True
    async with connect(f"{ws_url(app)}/?token={ADMIN}") as admin:
        assert (await call(admin, "/reset"))["result"] is True


async def test_a_wrong_token_is_refused_before_the_upgrade(make_app: AppFactory) -> None:
    app = await make_app(client_tokens=TOKENS)
    with pytest.raises(InvalidStatus) as info:
        async with connect(f"{ws_url(app)}/?token=guess"):
            pass
    assert info.value.response.status_code == 401


async def test_without_a_token_a_client_gets_only_refusals(make_app: AppFactory) -> None:
    app = await make_app(client_tokens=TOKENS)
    async with connect(ws_url(app)) as ws:
        await send_json(ws, {"op": "subscribe", "topic": "/odom"})
        status = await recv_until(ws, lambda m: m.get("op") == "status")
        assert "not authenticated" in status["msg"]
        assert "not authenticated" in (await call(ws, "/rosapi/topics"))["values"]
    assert not app.graph.topics.topics["/odom"].sinks


async def test_student_token_drives_only_its_own_robot(make_app: AppFactory) -> None:
    """Connected with r1's token: /r1/cmd_vel is accepted, /cmd_vel (another robot) refused."""
    app = await make_app(client_tokens=TOKENS)
    async with connect(f"{ws_url(app)}/?token=student-one-token") as ws:
        twist = {"linear": {"x": 0.2}, "angular": {"z": 0.0}}
        await send_json(ws, {"op": "publish", "topic": "/cmd_vel", "msg": twist, "id": "p"})
        status = await recv_until(ws, lambda m: m.get("op") == "status")
        assert "/r1/" in status["msg"]
        await send_json(ws, {"op": "subscribe", "topic": "/odom"})
        odom = await recv_until(ws, lambda m: m.get("topic") == "/odom")
        assert odom["msg"]["twist"]["twist"]["linear"]["x"] == 0.0
        assert app.world.robots[""].cmd_v == 0.0


async def test_roslibpy_connects_with_a_token_in_the_url(
    make_app: AppFactory, run_roslibpy: ClientRunner
) -> None:
    app = await make_app(client_tokens=TOKENS)
    result = await run_roslibpy(f"{ws_url(app)}/?token=everything-token", "topics")
    assert "/odom" in result["topics"]


AUTH_SECRET = "sixteen-chars-ok"


def signed_auth() -> dict[str, Any]:
    """The fields of a rosauth ``auth`` op for ``AUTH_SECRET``, valid for an hour from now."""
    t = int(time.time())
    fields: dict[str, Any] = {
        "client": "127.0.0.1",
        "dest": "127.0.0.1",
        "rand": "a1b2c3",
        "t": t,
        "level": "user",
        "end": t + 3600,
    }
    return {**fields, "mac": rosauth_mac(AUTH_SECRET, **fields)}


@pytest.mark.parametrize("lib", ["roslib1", "roslib2"])
async def test_roslibjs_authenticates_with_a_rosauth_mac(
    make_app: AppFactory, run_js: ClientRunner, lib: str
) -> None:
    """Ros.authenticate of roslibjs: a valid MAC lets it in, a wrong one closes the connection."""
    app = await make_app(auth_secret=AUTH_SECRET)
    fields = signed_auth()
    result = await run_js(lib, ws_url(app), "auth", fields)
    assert "/odom" in result["topics"]
    refused = await run_js(
        lib, ws_url(app), "auth", {**fields, "mac": "0" * 128, "expect_refusal": True}
    )
    assert refused["closed"] is True


async def test_roslibpy_authenticates_with_a_rosauth_mac(
    make_app: AppFactory, run_roslibpy: ClientRunner
) -> None:
    """Ros.authenticate of roslibpy (sent on connection): a valid MAC lets it list topics."""
    app = await make_app(auth_secret=AUTH_SECRET)
    result = await run_roslibpy(ws_url(app), "topics", {"authenticate": signed_auth()})
    assert "/odom" in result["topics"]


async def test_origin_allow_list_refuses_foreign_pages(make_app: AppFactory) -> None:
    app = await make_app(allowed_origins=("http://pi.local:8080",))
    with pytest.raises(InvalidStatus) as info:
        async with connect(ws_url(app), origin="http://evil.example"):  # type: ignore[arg-type]
            pass
    assert info.value.response.status_code == 403
    async with connect(ws_url(app), origin="http://pi.local:8080") as ws:  # type: ignore[arg-type]
        assert (await call(ws, "/rosapi/topics"))["result"] is True
    async with connect(ws_url(app)) as ws:  # roslibpy, Node: no Origin header
        assert (await call(ws, "/rosapi/topics"))["result"] is True


async def test_tls_serves_wss_and_https_with_the_given_certificate(
    make_app: AppFactory, certificate: tuple[Path, Path]
) -> None:
    certfile, keyfile = certificate
    app = await make_app(certfile=str(certfile), keyfile=str(keyfile))
    trust = ssl.create_default_context(cafile=str(certfile))
    async with connect(f"wss://127.0.0.1:{app.ws_port}", ssl=trust) as ws:
        assert (await call(ws, "/rosapi/topics"))["result"] is True
    status, body = await asyncio.to_thread(
        fetch, f"https://127.0.0.1:{app.http_port}/healthz", trust
    )
    assert status == 200 and json.loads(body)["status"] == "ok"
    with pytest.raises((ConnectionClosed, OSError, InvalidHandshake)):
        async with connect(f"ws://127.0.0.1:{app.ws_port}", open_timeout=3) as ws:
            await ws.recv()


async def test_the_command_serves_wss_and_https_with_certfile(
    certificate: tuple[Path, Path],
) -> None:
    """`simbridge --certfile --keyfile` (its own process: asyncio imported with ssl) serves TLS.

    Without --certfile the command keeps ssl out of asyncio's import (tests/test_footprint.py);
    with it, both ports speak TLS.
    """
    certfile, keyfile = certificate
    proc = await asyncio.create_subprocess_exec(
        *(sys.executable, "-m", "simbridge", "--host", "127.0.0.1", "--port", "0"),
        *("--http-port", "0", "--certfile", str(certfile), "--keyfile", str(keyfile)),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd="/tmp",
    )
    try:
        assert proc.stdout is not None
        line = (await asyncio.wait_for(proc.stdout.readline(), 30 * TIMEOUT_FACTOR)).decode()
        # the printed URLs are the TLS ones (what a user copies)
        ports = re.search(r"wss://127\.0\.0\.1:(\d+)/\s+page https://127\.0\.0\.1:(\d+)/", line)
        assert ports, line
        trust = ssl.create_default_context(cafile=str(certfile))
        async with connect(f"wss://127.0.0.1:{ports.group(1)}", ssl=trust) as ws:
            assert (await call(ws, "/rosapi/topics"))["result"] is True
        status, body = await asyncio.to_thread(
            fetch, f"https://127.0.0.1:{ports.group(2)}/healthz", trust
        )
        assert status == 200 and json.loads(body)["status"] == "ok"
    finally:
        proc.terminate()
        _, err = await asyncio.wait_for(proc.communicate(), 20 * TIMEOUT_FACTOR)
    assert proc.returncode == 0 and b"Traceback" not in err


async def test_roslibjs_connects_over_wss(
    make_app: AppFactory,
    run_js: ClientRunner,
    certificate: tuple[Path, Path],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An unmodified roslibjs (Node, trusting the test's CA) uses wss:// like an https page."""
    certfile, keyfile = certificate
    app = await make_app(certfile=str(certfile), keyfile=str(keyfile))
    monkeypatch.setenv("NODE_EXTRA_CA_CERTS", str(certfile))
    result = await run_js("roslib2", f"wss://127.0.0.1:{app.ws_port}", "topics")
    assert "/odom" in result["topics"]
