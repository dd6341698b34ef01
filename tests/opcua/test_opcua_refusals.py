"""Secure by default: every way in that the station must refuse, against the real server
process (``station serve --opcua … --simulated``), and the ways in that must work."""

from __future__ import annotations

import asyncio

import pytest
from asyncua import Client, ua
from asyncua.ua.uaerrors import BadUserAccessDenied, UaError

from tests.opcua.clients import PASSWORDS, connected, read, station

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


async def test_endpoints_offer_only_signed_and_encrypted_channels(served) -> None:
    endpoints = await Client(served.url, timeout=20).connect_and_get_server_endpoints()
    modes = {(e.SecurityPolicyUri.rsplit("#", 1)[-1], e.SecurityMode) for e in endpoints}
    assert modes == {(p, m) for p in ("Basic256Sha256", "Aes256_Sha256_RsaPss")
                     for m in (ua.MessageSecurityMode.Sign, ua.MessageSecurityMode.SignAndEncrypt)}
    tokens = {t.TokenType for e in endpoints for t in e.UserIdentityTokens}
    assert tokens == {ua.UserTokenType.UserName, ua.UserTokenType.Certificate}  # no Anonymous


async def test_refused_ways_in(served, pki) -> None:
    # anonymous, over a trusted secure channel
    with pytest.raises((UaError, asyncio.TimeoutError, ConnectionError)) as anonymous:
        async with connected(served.url, pki.client_cert, pki.client_key):
            pass
    assert "IdentityTokenRejected" in type(anonymous.value).__name__ + str(anonymous.value)
    # a wrong password
    with pytest.raises(BadUserAccessDenied):
        async with connected(served.url, pki.client_cert, pki.client_key, user="line", password="not-it"):
            pass
    # an unknown user, with another user's password
    with pytest.raises(BadUserAccessDenied):
        async with connected(served.url, pki.client_cert, pki.client_key, user="nobody", password=PASSWORDS["line"]):
            pass
    # the right password from a client whose certificate is not in the trust list
    with pytest.raises((UaError, asyncio.TimeoutError, ConnectionError)) as stranger:
        async with connected(served.url, pki.stranger_cert, pki.stranger_key, user="line", password=PASSWORDS["line"]):
            pass
    assert "Untrusted" in type(stranger.value).__name__ + str(stranger.value)
    # no security at all: there is no such endpoint
    with pytest.raises((UaError, asyncio.TimeoutError, ConnectionError)):
        async with connected(served.url, None, None, user="line", password=PASSWORDS["line"]):
            pass


async def test_observer_reads_but_may_not_start(served, pki) -> None:
    async with connected(served.url, pki.client_cert, pki.client_key, user="watch", password=PASSWORDS["watch"],
                         policy="Aes256Sha256RsaPss", mode="Sign") as client:
        idx, node = await station(client)
        assert await read(node, idx, "State") == "Idle"
        for method in ("StartCalibration", "StartRecheck", "Abort", "Acknowledge", "Pause", "Resume"):
            with pytest.raises(BadUserAccessDenied):
                await node.call_method(f"{idx}:{method}")
        assert await read(node, idx, "State") == "Idle"  # nothing started
        assert await read(node, idx, "RunId") == 0


async def test_x509_user_is_an_observer(served, pki) -> None:
    client = Client(served.url, timeout=20)
    await client.set_security_string(f"Basic256Sha256,SignAndEncrypt,{pki.client_cert},{pki.client_key}")
    await client.load_client_certificate(str(pki.user_cert))  # the user's identity: its certificate
    await client.load_private_key(str(pki.user_key))
    async with client:
        idx, node = await station(client)
        assert await read(node, idx, "State") == "Idle"
        with pytest.raises(BadUserAccessDenied):
            await node.call_method(f"{idx}:StartRecheck")
