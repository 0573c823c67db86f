"""Byte streams: the in-memory pipe, TCP on loopback, a pseudo-terminal via pyserial-asyncio."""

import asyncio
import os

import pytest

from afa import EDevIO, TransportClosed
from afa.tasks import TaskGroup
from afa.transport import DeviceOpener, SerialSpec, TcpSpec, memory_pipe, open_serial, open_tcp


async def test_memory_pipe_carries_bytes_both_ways_in_order():
    host, device = memory_pipe("test")
    await host.write(b"abc")
    await host.write(b"def")
    assert await device.read() == b"abc"
    assert await device.read(2) == b"de"
    assert await device.read() == b"f"
    device.write_nowait(b"reply")
    assert await host.read() == b"reply"


async def test_memory_pipe_end_of_stream_after_close():
    host, device = memory_pipe("test")
    await device.write(b"last words")
    await device.close()
    assert await host.read() == b"last words"
    with pytest.raises(TransportClosed):
        await host.read()
    with pytest.raises(EDevIO):
        await host.write(b"x")  # the other end is gone


async def test_a_waiting_reader_wakes_on_close():
    host, device = memory_pipe("test")
    reader = asyncio.get_running_loop().create_task(host.read())
    await asyncio.sleep(0)
    device.close_nowait()
    with pytest.raises(TransportClosed):
        await reader


async def test_tcp_on_loopback():
    received = []

    async def handle(reader, writer):
        received.append(await reader.readexactly(5))
        writer.write(b"world")
        await writer.drain()
        writer.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    async with server:
        stream = await open_tcp("127.0.0.1", port)
        await stream.write(b"hello")
        data = b""
        with pytest.raises(TransportClosed):
            while True:
                data += await stream.read()
        await stream.close()
    assert received == [b"hello"] and data == b"world"


async def test_tcp_connection_refused_is_edevio():
    server = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    server.close()
    await server.wait_closed()
    with pytest.raises(EDevIO, match=f"127.0.0.1:{port}"):
        await open_tcp("127.0.0.1", port)


async def test_serial_through_a_pseudo_terminal():
    controller, worker = os.openpty()
    path = os.ttyname(worker)
    import tty

    tty.setraw(controller)
    stream = await open_serial(path, 115200)
    try:
        os.write(controller, b"$GPGGA")
        data = b""
        while len(data) < 6:
            data += await stream.read()
        assert data == b"$GPGGA"
        await stream.write(b"log bestposa\r\n")
        loop = asyncio.get_running_loop()
        echoed = await loop.run_in_executor(None, os.read, controller, 100)
        assert echoed == b"log bestposa\r\n"
    finally:
        await stream.close()
        os.close(controller)
        os.close(worker)


async def test_a_missing_serial_port_is_edevio():
    with pytest.raises(EDevIO, match="/dev/does-not-exist"):
        await open_serial("/dev/does-not-exist", 9600)


async def test_device_opener_prefers_overrides():
    host, _device = memory_pipe()

    async def fake(spec):
        assert spec == SerialSpec("/dev/ttyS0", 9600)
        return host

    opener = DeviceOpener({"Gps": fake})
    assert await opener.open("Gps", SerialSpec("/dev/ttyS0", 9600)) is host
    with pytest.raises(EDevIO):
        await opener.open("Laser", TcpSpec("127.0.0.1", 1))


async def test_two_components_on_one_serial_port_share_the_connection():
    import tty

    controller, worker = os.openpty()
    tty.setraw(controller)
    path = os.ttyname(worker)
    opener = DeviceOpener()  # a pseudo-terminal: a real serial port made for the test
    async with TaskGroup():  # the shared port's tasks belong to someone
        await _share_one_port(opener, path, controller, worker)


async def _share_one_port(opener, path, controller, worker):
    odometry = await opener.open("RaptorOdometryService", SerialSpec(path, 115200))
    control = await opener.open("RaptorService", SerialSpec(path, 115200))
    loop = asyncio.get_running_loop()
    try:
        os.write(controller, b"report")
        for tap in (odometry, control):
            data = b""
            while len(data) < 6:
                data += await tap.read()
            assert data == b"report"  # both components see every byte the device sends
        await control.write(b"cmd-a")
        await odometry.write(b"cmd-b")
        received = b""
        while len(received) < 10:
            received += await loop.run_in_executor(None, os.read, controller, 100)
        assert sorted([received[:5], received[5:]]) == [b"cmd-a", b"cmd-b"]
    finally:
        await odometry.close()
        await control.close()
        os.close(controller)
        os.close(worker)
