"""A minimal Foxglove WebSocket client for the tests: lists the advertised channels, subscribes,
and decodes each message with the protobuf schema its channel advertised."""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import time

import websockets
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

SUBPROTOCOL = "foxglove.sdk.v1"


def decoder(channel: dict):
    """A function bytes -> protobuf message for an advertised channel (its FileDescriptorSet)."""
    assert channel["encoding"] == "protobuf" and channel["schemaEncoding"] == "protobuf", channel
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))
    return cls.FromString


async def _collect(url: str, want: set[str], timeout: float, garbage: list) -> tuple[dict, dict, list]:
    channels: dict[str, dict] = {}
    received: dict[str, object] = {}
    replies: list[dict] = []
    decoders: dict[int, tuple[str, object]] = {}
    end = time.monotonic() + timeout
    async with websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as ws:
        for bad in garbage:
            await ws.send(bad)
        next_sub = 1
        while time.monotonic() < end and not want <= set(received):
            try:
                raw = await asyncio.wait_for(ws.recv(), max(0.05, end - time.monotonic()))
            except asyncio.TimeoutError:
                break
            if isinstance(raw, str):
                msg = json.loads(raw)
                if msg["op"] == "advertise":
                    subs = []
                    for ch in msg["channels"]:
                        channels[ch["topic"]] = ch
                        decoders[next_sub] = (ch["topic"], decoder(ch))
                        subs.append({"id": next_sub, "channelId": ch["id"]})
                        next_sub += 1
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                elif msg["op"] == "status":
                    replies.append(msg)
            elif raw[0] == 1:  # message data: opcode, subscription id, log time, payload
                sub_id, _ = struct.unpack_from("<IQ", raw, 1)
                topic, decode = decoders[sub_id]
                if topic not in received:
                    received[topic] = decode(raw[13:])
    return channels, received, replies


def watch(port: int, want: set[str], timeout: float = 60.0, garbage: list | None = None,
          host: str = "127.0.0.1") -> tuple[dict, dict, list]:
    """Connect to ``ws://host:port``, send ``garbage`` first, subscribe to every channel; return
    (channels by name, the first decoded message of each channel, the server's status replies)
    once every channel of ``want`` sent a message or ``timeout`` [s] passed."""
    return asyncio.run(_collect(f"ws://{host}:{port}", want, timeout, list(garbage or [])))


def wait_for_server(port: int, timeout: float, host: str = "127.0.0.1") -> bool:
    """Whether a WebSocket server answers on ``port`` within ``timeout`` [s]."""
    async def attempt() -> bool:
        try:
            async with websockets.connect(f"ws://{host}:{port}", subprotocols=[SUBPROTOCOL], open_timeout=1.0):
                return True
        except (OSError, asyncio.TimeoutError, websockets.exceptions.WebSocketException):
            return False

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if asyncio.run(attempt()):
            return True
        time.sleep(0.5)
    return False
