"""The console's web server on loopback: the page, the WebSocket, the guard, the actions,
and the command line. Real sockets, a real aiohttp client; the system runs on the wall
clock (a second or two per test)."""

import argparse
import asyncio
import importlib.util
import json
import logging
import socket
from pathlib import Path

import aiohttp
import numpy as np
import pytest
from console_synthetic import synthetic_system

from afa import WallClock
from afa.cli import main
from afa.console import Console, ConsoleError, ConsoleOptions, add_arguments, from_args
from afa.console.frames import decode_frame
from afa.console.guard import TOKEN_HEADER
from afa.console.server import _LOG_LIMIT
from afa.testing import until
from idl import Position3DIDL, TimeIDL, TravMapArrayEventIDL

ROOT = Path(__file__).resolve().parents[2]


async def running(control=False, **options):
    system = synthetic_system(WallClock())
    console = Console(system, ConsoleOptions(port=0, control=control, **options))
    await console.start()
    await system.start()
    return system, console


async def finish(system, console):
    await system.stop()
    await console.stop()


async def call(http, method, url, **options):
    """(status, JSON body or None), the connection released."""
    async with http.request(method, url, **options) as response:
        try:
            body = await response.json()
        except (aiohttp.ContentTypeError, ValueError):
            body = None
        return response.status, body


def base(console):
    return f"http://127.0.0.1:{console.port}"


async def test_the_page_and_its_files_come_from_the_package_with_a_strict_policy():
    system, console = await running()
    try:
        async with aiohttp.ClientSession() as http:
            page = await http.get(base(console) + "/")
            assert page.status == 200 and "text/html" in page.headers["Content-Type"]
            assert '<script type="module" src="/static/js/main.js">' in await page.text()
            policy = page.headers["Content-Security-Policy"]
            assert "default-src 'none'" in policy and "connect-src 'self'" in policy
            for path in ("/static/js/main.js", "/static/js/wire.js", "/static/console.css",
                         "/static/vendor/three.module.js", "/static/vendor/three.core.js"):
                async with http.get(base(console) + path) as response:
                    assert response.status == 200, path
            async with http.get(base(console) + "/static/js/views/maps.js") as script:
                assert script.headers["Content-Type"].startswith("text/javascript")
            assert (await call(http, "GET", base(console) + "/static/../guard.py"))[0] == 404
            assert (await call(http, "GET", base(console) + "/static/nothing.js"))[0] == 404
    finally:
        await finish(system, console)


async def test_other_host_names_and_other_sites_are_refused():
    system, console = await running(control=True)
    try:
        async with aiohttp.ClientSession() as http:
            status, _ = await call(http, "GET", base(console) + "/",
                                   headers={"Host": "evil.example"})
            assert status == 403
            status, body = await call(http, "POST", base(console) + "/api/vehicle/stop",
                                      json={}, headers={"Origin": "http://evil.example"})
            assert status == 403 and "not accepted" in body["error"]
            # a WebSocket handshake from another site
            status, _ = await call(http, "GET", base(console) + "/ws", headers={
                "Origin": "http://evil.example", "Connection": "Upgrade",
                "Upgrade": "websocket", "Sec-WebSocket-Version": "13",
                "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="})
            assert status == 403
            status, _ = await call(http, "POST", base(console) + "/api/vehicle/stop",
                                   data="x=1")
            assert status == 415
    finally:
        await finish(system, console)


async def test_beyond_loopback_a_rebinding_name_is_refused_and_ip_addresses_are_not():
    """DNS rebinding against a console on every interface: the attacker's page, under its
    own name resolved to this machine, reads nothing and commands nothing."""
    system, console = await running(control=True, host="0.0.0.0", host_names=["vehicle.lan"])
    try:
        port = console.port
        async with aiohttp.ClientSession() as http:
            url = f"http://127.0.0.1:{port}"
            attacker = {"Host": f"attacker.example:{port}",
                        "Origin": f"http://attacker.example:{port}"}
            assert (await call(http, "GET", url + "/api/status", headers=attacker))[0] == 403
            status, body = await call(http, "POST", url + "/api/vehicle/stop", json={},
                                      headers=attacker)
            assert status == 403 and "not this console" in body["error"]
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await http.ws_connect(url + "/ws", headers=attacker)
            assert refused.value.status == 403
            assert system.components["RaptorService"].calls == []
            for host in (f"127.0.0.1:{port}", f"vehicle.lan:{port}"):
                own = {"Host": host, "Origin": f"http://{host}"}
                assert (await call(http, "GET", url + "/api/status", headers=own))[0] == 200
                status, _ = await call(http, "POST", url + "/api/vehicle/stop", json={},
                                       headers=own)
                assert status == 200
        assert system.components["RaptorService"].calls == ["stopVehicle"] * 2
    finally:
        await finish(system, console)


def test_the_command_line_lists_the_consoles_host_names(capsys):
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--console", "0.0.0.0:8765", "--console-host-name",
                              "Vehicle.lan", "--console-host-name", "ops"])
    console = from_args(args, synthetic_system(WallClock()))
    assert console.options.host_names == ["vehicle.lan", "ops"]
    assert console.guard.check_request("vehicle.lan:8765", None) is None
    assert console.guard.check_request("ops:8765", None) is None
    assert console.guard.check_request("attacker.example:8765", None) is not None
    with pytest.raises(SystemExit):
        parser.parse_args(["--console", "0", "--console-host-name", "vehicle.lan:8765"])
    assert "not a host name" in capsys.readouterr().err


async def test_without_the_control_option_commands_are_refused_but_stop_vehicle_works():
    system, console = await running(control=False)
    control = system.components["RaptorService"]
    synthetic = system.components["synthetic"]
    try:
        async with aiohttp.ClientSession() as http:
            for path in ("/api/components/synthetic/restart", "/api/vehicle/start",
                         "/api/vehicle/arbiter-on"):
                refused = await http.post(base(console) + path, json={},
                                          headers={TOKEN_HEADER: console.guard.token})
                assert refused.status == 403, path
                assert "--console-control" in (await refused.json())["error"]
            assert synthetic.state.value == "running" and synthetic.restarts == 0
            stop = await http.post(base(console) + "/api/vehicle/stop", json={},
                                   headers={"Origin": base(console)})
            assert stop.status == 200 and (await stop.json())["served_by"] == "RaptorMotion"
        assert control.calls == ["stopVehicle"]
        assert console.url == base(console) + "/"  # no token without control
    finally:
        await finish(system, console)


async def test_with_the_control_option_commands_need_the_token():
    system, console = await running(control=True)
    try:
        assert console.url.endswith(f"/#token={console.guard.token}")
        async with aiohttp.ClientSession() as http:
            url = base(console) + "/api/components/synthetic/restart"
            assert (await call(http, "POST", url, json={}))[0] == 403
            for wrong in ("guess", "é"):
                assert (await call(http, "POST", url, json={},
                                   headers={TOKEN_HEADER: wrong}))[0] == 403
            before = system.components["synthetic"]._scope
            done = await http.post(url, json={}, headers={TOKEN_HEADER: console.guard.token})
            assert done.status == 200 and (await done.json())["state"] == "running"
            assert system.components["synthetic"]._scope is not before  # a new life
            token = {TOKEN_HEADER: console.guard.token}
            assert (await call(http, "POST", base(console) + "/api/components/nobody/restart",
                               json={}, headers=token))[0] == 404
            assert (await call(http, "POST", base(console) + "/api/components/synthetic/explode",
                               json={}, headers=token))[0] == 400
            assert (await call(http, "POST", base(console) + "/api/vehicle/arbiter-on",
                               json={}, headers=token))[0] == 200
            replay = await http.post(base(console) + "/api/replay/play", json={})
            assert replay.status == 409 and "not a recording" in (await replay.json())["error"]
        assert system.components["RaptorService"].calls == ["setArbiter(True)"]
    finally:
        await finish(system, console)


async def test_the_websocket_says_hello_then_sends_what_was_asked_for():
    system, console = await running()
    try:
        async with aiohttp.ClientSession() as http:
            ws = await http.ws_connect(base(console) + "/ws", headers={"Origin": base(console)})
            hello, events = decode_frame(await ws.receive_bytes(timeout=5))
            assert hello["kind"] == "hello" and events == [] and hello["control"] is False
            assert hello["policies"]["map.traverse"]["rate"] == 1.0
            await ws.send_str("not json")
            await ws.send_str(json.dumps({"op": "subscribe", "kinds": {"arcs.vote": None,
                                                                       "status": None}}))
            seen = set()
            while not {"arcs.vote", "status"} <= seen:
                header, events = decode_frame(await ws.receive_bytes(timeout=5))
                seen.add(header["kind"])
                if header["kind"] == "arcs.vote":
                    assert events[0].body.behaviour == header["stream"].split("/")[1]
            assert seen == {"arcs.vote", "status"}
            status = await (await http.get(base(console) + "/api/status")).json()
            assert [row["name"] for row in status["components"]] == [
                "modelServer", "synthetic", "RaptorService"]
            await ws.close()
    finally:
        await finish(system, console)


async def test_input_the_server_cannot_use_is_refused_or_ignored_and_counted():
    """Deeply nested JSON (too deep for Python's parser) and numbers beyond any float:
    a 400 for a request, an ignored (and counted) WebSocket message; the socket stays."""
    system, console = await running()
    try:
        async with aiohttp.ClientSession() as http:
            status, body = await call(http, "POST", base(console) + "/api/replay/seek",
                                      data="[" * 20000 + "]" * 20000,
                                      headers={"Content-Type": "application/json"})
            assert status == 400 and "not JSON" in body["error"]
            ws = await http.ws_connect(base(console) + "/ws", headers={"Origin": base(console)})
            assert decode_frame(await ws.receive_bytes(timeout=5))[0]["kind"] == "hello"
            await ws.send_str("[" * 30000)
            await ws.send_str('{"op": "subscribe", "kinds": ["status"]}')
            await ws.send_str('{"op": "subscribe", "kinds": {"status": 1%s}}' % ("0" * 400))
            header, _ = decode_frame(await ws.receive_bytes(timeout=5))
            assert header["kind"] == "status"  # the huge rate is the kind's maximum
            status = await (await http.get(base(console) + "/api/status")).json()
            assert status["console"]["rejected"] == {"message": 2}
            await ws.close()
    finally:
        await finish(system, console)


async def test_pages_beyond_the_limit_are_refused_until_one_closes():
    """A client opening WebSockets in a loop: the server copies every frame to each page,
    so beyond ``max_pages`` the next is refused (503) and counted; a page that closes
    frees its place."""
    system, console = await running(max_pages=2)
    url, origin = base(console) + "/ws", {"Origin": base(console)}
    try:
        async with aiohttp.ClientSession() as http:
            pages = [await http.ws_connect(url, headers=origin) for _ in range(2)]
            for page in pages:
                assert decode_frame(await page.receive_bytes(timeout=5))[0]["kind"] == "hello"
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await http.ws_connect(url, headers=origin)
            assert refused.value.status == 503
            status = await (await http.get(base(console) + "/api/status")).json()
            assert status["console"]["rejected"] == {"page": 1}
            await pages[0].close()
            await until(lambda: len(console.hub.sessions) == 1, WallClock(), timeout=10,
                        what="the closed page's place freed")
            again = await http.ws_connect(url, headers=origin)
            assert decode_frame(await again.receive_bytes(timeout=5))[0]["kind"] == "hello"
            await again.close()
            await pages[1].close()
    finally:
        await finish(system, console)


async def raw_request(port, request):
    """The server's whole answer to ``request`` (bytes), sent as is."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(request)
        return await reader.read()
    finally:
        writer.close()
        await writer.wait_closed()


async def test_refused_and_malformed_requests_are_logged_a_few_times_then_counted(caplog):
    system, console = await running()
    times = _LOG_LIMIT + 3
    try:
        with caplog.at_level(logging.WARNING):
            for _ in range(times):
                malformed = await raw_request(console.port, (
                    b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nHost: evil.example\r\n\r\n"))
                assert malformed.split(b"\r\n")[0].endswith(b"400 Bad Request")
                refused = await raw_request(console.port, (
                    b"GET /api/status HTTP/1.1\r\nHost: evil.example\r\n"
                    b"Connection: close\r\n\r\n"))
                assert refused.startswith(b"HTTP/1.1 403")
        async with aiohttp.ClientSession() as http:
            status = await (await http.get(base(console) + "/api/status")).json()
        assert status["console"]["rejected"] == {"malformed": times, "request": times}
        lines = [record.getMessage() for record in caplog.records]
        malformed_lines = [line for line in lines if "malformed request" in line]
        refused_lines = [line for line in lines if "refused GET /api/status" in line]
        assert len(malformed_lines) == len(refused_lines) == _LOG_LIMIT
        assert "Duplicate 'Host' header" in malformed_lines[0]
        assert "only counted" in malformed_lines[-1] and "only counted" in refused_lines[-1]
        assert [record for record in caplog.records if record.exc_info] == []  # no traceback
    finally:
        await finish(system, console)


def text_frame(text):
    """A client's WebSocket text frame (masked with a zero key: the payload as is)."""
    payload = text.encode()
    assert len(payload) < 126
    return bytes([0x81, 0x80 | len(payload)]) + bytes(4) + payload


def huge_map(system, cells=1500):
    """A traversability map far larger than the socket buffers (two 9 MB layers)."""
    layer = np.zeros((cells, cells), dtype=np.float32)
    return TravMapArrayEventIDL(
        time=TimeIDL.from_seconds(system.clock.now()), frame="World", mapPose=np.eye(4),
        initialUTM=np.zeros(3), gridsize=0.5, originX=0.0, originY=0.0, rows=cells,
        cols=cells, hazard=layer, goodness=layer, vehiclePosition=Position3DIDL(x=0, y=0))


@pytest.mark.timeout(60)
async def test_stop_does_not_wait_for_a_browser_that_stops_reading():
    """A client that subscribes to maps and never reads again: the server's sends and its
    close frame cannot leave, yet stop() completes (the connection is dropped)."""
    system, console = await running()
    loop = asyncio.get_running_loop()
    client = socket.socket()
    client.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    client.setblocking(False)
    try:
        await loop.sock_connect(client, ("127.0.0.1", console.port))
        await loop.sock_sendall(client, (
            f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{console.port}\r\nUpgrade: websocket\r\n"
            "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n").encode())
        assert (await loop.sock_recv(client, 4096)).startswith(b"HTTP/1.1 101")
        # once per 100 s: the synthetic Traverse maps cannot fill the buffers before it
        await loop.sock_sendall(client, text_frame(json.dumps(
            {"op": "subscribe", "kinds": {"map.traverse": 0.01}})))
        system.channel.publish(system.robot, "Huge", huge_map(system))

        def huge_map_sent():
            return any(s.statistics()["streams"].get("map.traverse/Huge", {}).get("sent")
                       for s in console.hub.sessions)

        await until(huge_map_sent, WallClock(), timeout=30, what="the map handed to the socket")
        await finish(system, console)  # never read: returns all the same
        assert console.hub.sessions == set()
    finally:
        client.close()


async def test_a_busy_port_and_a_missing_extra_are_clear_errors(monkeypatch):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        console = Console(synthetic_system(WallClock()), ConsoleOptions(port=port))
        with pytest.raises(ConsoleError, match=f"cannot listen on 127.0.0.1:{port}"):
            await console.start()
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "aiohttp" else real(name, *a))
    with pytest.raises(ConsoleError, match=r"pip install 'afa\[console\]'"):
        Console(synthetic_system(WallClock()))


def test_the_command_line_serves_the_console_and_refuses_control_without_it(capsys):
    config = str(ROOT / "configs" / "raptor.xml")
    assert main(["run", config, "--sim", "--fast", "--duration", "1",
                 "--console-control"]) == 1
    assert "--console-control needs --console" in capsys.readouterr().err
    assert main(["run", config, "--sim", "--fast", "--duration", "2", "--console", "0"]) == 0
    err = capsys.readouterr().err
    assert "afa: console at http://127.0.0.1:" in err and "#token" not in err
    with pytest.raises(SystemExit):
        main(["run", config, "--console", "nowhere"])
    assert "is not [HOST:]PORT" in capsys.readouterr().err


def test_every_file_of_the_page_is_package_data():
    """A file under afa/console/static that no package-data pattern names would be
    missing from a wheel (the page would 404 on an installed afa)."""
    import fnmatch
    import tomllib

    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"]["afa.console"]
    static = ROOT / "afa" / "console"
    files = [path.relative_to(static).as_posix()
             for path in (static / "static").rglob("*") if path.is_file()]
    assert len(files) >= 17
    missing = [f for f in files if not any(fnmatch.fnmatch(f, p) and f.count("/") ==
                                           p.count("/") for p in patterns)]
    assert missing == []
