"""The tests' OPC UA clients: asyncua's Client over the secured endpoints, as a line's MES would."""

from __future__ import annotations

import asyncio
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from asyncua import Client, Node, ua

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "examples" / "scara600" / "cell.toml"
STATION_NS = "urn:robot-calibration-station:opcua:station"
#: asyncua's clients (the tests' and its uaread) announce this application URI: a trusted client
#: certificate must name it (the server checks the certificate's URI against the client's)
CLIENT_URI = "urn:example.org:FreeOpcUa:opcua-asyncio"
PASSWORDS = {"line": "mes-operator-pw", "watch": "observer-pw"}


def make_client(url: str, cert: Path | None, key: Path | None, *, user: str | None = None, password: str | None = None,
                policy: str = "Basic256Sha256", mode: str = "SignAndEncrypt") -> tuple[Client, str | None]:
    client = Client(url, timeout=20)
    if user is not None:
        client.set_user(user)
        client.set_password(password or "")
    security = f"{policy},{mode},{cert},{key}" if cert is not None else None
    return client, security


@asynccontextmanager
async def connected(url: str, cert: Path | None, key: Path | None, **kwargs: Any):
    client, security = make_client(url, cert, key, **kwargs)
    if security is not None:
        await client.set_security_string(security)
    async with client:
        yield client


async def station(client: Client) -> tuple[int, Node]:
    idx = await client.get_namespace_index(STATION_NS)
    return idx, await client.nodes.objects.get_child([f"{idx}:CalibrationStation"])


async def read(node: Node, idx: int, *path: str) -> Any:
    return await (await node.get_child([f"{idx}:{p}" for p in path])).read_value()


class Collector:
    """A subscription handler: data changes and events, as they come."""

    def __init__(self) -> None:
        self.changes: list[tuple[str, Any]] = []
        self.events: asyncio.Queue[Any] = asyncio.Queue()

    def datachange_notification(self, node: Node, val: Any, data: Any) -> None:
        self.changes.append((str(node.nodeid.Identifier), val))

    def event_notification(self, event: Any) -> None:
        self.events.put_nowait(event)

    def values(self, suffix: str) -> list[Any]:
        return [v for k, v in self.changes if k.endswith(suffix)]


async def subscribe_station(client: Client, idx: int, node: Node, handler: Collector, *names: str) -> Any:
    """Subscribe to ``names`` of the station and to its ResultReady events."""
    sub = await client.create_subscription(20, handler)
    for name in names:
        await sub.subscribe_data_change(await node.get_child([f"{idx}:{name}"]))
    await sub.subscribe_events(node, client.get_node(ua.NodeId(1005, idx)))  # CalibrationResultReadyEventType
    return sub
