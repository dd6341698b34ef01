"""``station serve --opcua CONFIG``: the station as a secure OPC UA server for one cell.

Endpoints: Basic256Sha256 and Aes256_Sha256_RsaPss, each Sign and SignAndEncrypt; no None
endpoint, no anonymous token (OPC 10000-7 profiles; docs/opcua.md has the ports and the firewall
rule). Users from the users file (security.py); client certificates from the trust-list folder.
"""

from __future__ import annotations

import asyncio
import datetime as dt
import errno
import logging
import math
import signal
import socket
import sys
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from asyncua import Server, ua
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
from cryptography import x509

from station.cell.config.cell_config import CellConfig, load_config
from station.cell.session.calibrate import CellRequest
from station.errors import ConfigError
from station.ui.opcua.guard import bound_logging
from station.ui.opcua.model import CellFacts, OffsetParameter, build_instances, load_models
from station.ui.opcua.security import SERVER_CERT, SERVER_KEY, TRUSTED, StationRuleset, StationUserManager, read_users
from station.ui.opcua.service import StationService
from station.ui.simulated_cell import load_cell

log = logging.getLogger(__name__)

#: the IANA-registered port of OPC UA's binary protocol (opc.tcp), OPC 10000-6 §7.2
DEFAULT_PORT = 4840
#: the only policies offered (OPC 10000-7: SecurityPolicy [A] Aes256-Sha256-RsaPss, [B] Basic256Sha256)
POLICIES = (ua.SecurityPolicyType.Basic256Sha256_Sign, ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
            ua.SecurityPolicyType.Aes256Sha256RsaPss_Sign, ua.SecurityPolicyType.Aes256Sha256RsaPss_SignAndEncrypt)


@dataclass(frozen=True)
class ServeOptions:
    config: str
    users: str
    pki: str | None = None  # a folder made by --init-pki: own/cert.der, own/private/key.pem, trusted/
    cert: str | None = None  # or the certificate and key supplied
    key: str | None = None
    trust: str | None = None  # the trust list (default PKI/trusted)
    host: str = "0.0.0.0"
    port: int = DEFAULT_PORT
    simulated: bool = False
    seed: int | None = None
    time_scale: float = 0.0
    db: str = "runs.sqlite"


def _paths(opts: ServeOptions) -> tuple[Path, Path, Path]:
    pki = Path(opts.pki) if opts.pki else None
    cert = Path(opts.cert) if opts.cert else (pki / SERVER_CERT if pki else None)
    key = Path(opts.key) if opts.key else (pki / SERVER_KEY if pki else None)
    trust = Path(opts.trust) if opts.trust else (pki / TRUSTED if pki else None)
    if cert is None or key is None:
        raise ConfigError("the OPC UA server needs its certificate and key: give --pki DIR (made by 'station serve "
                          "--init-pki DIR') or --cert FILE --key FILE")
    if trust is None:
        raise ConfigError("give --trust DIR: the folder of the client certificates the station trusts")
    for what, p in (("certificate", cert), ("key", key)):
        if not p.is_file():
            raise ConfigError(f"no {what} file {p}: make one with 'station serve --init-pki DIR', or supply it")
    if not trust.is_dir():
        raise ConfigError(f"no trust-list folder {trust}: create it and copy the trusted client certificates into it")
    return cert, key, trust


def cell_facts(cfg: CellConfig) -> CellFacts:
    joints = [t for t in cfg.model.transforms if t.joint is not None]
    return CellFacts(cell=cfg.name, robot_model=cfg.model.name, robot_description=cfg.model.description,
                     robot_serial=cfg.identity.robot_serial, controller=cfg.identity.controller,
                     axes=tuple((f"Axis{j}", str(t.joint)) for j, t in enumerate(joints, start=1)),
                     body_certificate_id=cfg.body_certificate.id, body_certificate_date=cfg.body_certificate.date,
                     body_points=len(cfg.point_ids))


def offset_parameters(cfg: CellConfig) -> list[OffsetParameter | None]:
    """Per joint: the parameter that is its zero offset (the yaw of its transform for a revolute
    joint, in degrees; the z of it for a prismatic one, in mm), its index and nominal value."""
    out: list[OffsetParameter | None] = []
    for t in cfg.model.transforms:
        if t.joint is None:
            continue
        revolute = str(t.joint) == "revolute"
        name = f"{t.name}.{'yaw' if revolute else 'z'}"
        try:
            i = cfg.model.param_index(name)
        except (KeyError, ValueError):
            out.append(None)
            continue
        out.append(OffsetParameter(i, name, float(cfg.model.nominal[i]), math.degrees(1.0) if revolute else 1.0))
    return out


def application_uri(cert_path: Path) -> str:
    """The URI in the certificate's subjectAltName: the server's ApplicationUri must equal it."""
    cert = x509.load_der_x509_certificate(cert_path.read_bytes())
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName)
        uris = san.value.get_values_for_type(x509.UniformResourceIdentifier)
    except x509.ExtensionNotFound:
        uris = []
    if not uris:
        raise ConfigError(f"{cert_path}: the certificate names no application URI (subjectAltName URI); OPC UA needs one")
    return str(uris[0])


class TrustList(TrustStore):
    """asyncua's trust store, which fails on an empty folder ("can't create an empty store": the
    cryptography library's Store refuses no certificates) where docs/opcua.md's first step leaves
    one: an empty trust list trusts no client, it is not an error."""

    async def load_trust(self) -> None:
        certs = []
        for location in self.trust_locations:
            certs.extend(await self._load_trust_location(location))
        self._trust_store = x509.verification.Store(certs) if certs else None  # None: is_trusted is False


#: the station's product URI (its application URIs are this and the host name, command.URI_PREFIX)
PRODUCT_URI = "urn:robot-calibration-station"
PRODUCT_NAME = "calibration-station"


def build_info() -> tuple[str, str, str, str, str, dt.datetime]:
    """BuildInfo (OPC 10000-5 §12.4): the station's product URI, manufacturer (the package names
    none: empty), product name, version (the installed package's), build (its git commit when it
    runs from a checkout, else the version) and build date (the commit's, else the package's files')."""
    from station.ui.report.provenance import commit_date, git_commit

    version = _package_version()
    when = commit_date() or dt.datetime.fromtimestamp(Path(__file__).stat().st_mtime, dt.timezone.utc)
    return PRODUCT_URI, "", PRODUCT_NAME, version, git_commit() or version, when


def _package_version() -> str:
    try:
        return metadata.version(PRODUCT_NAME)
    except metadata.PackageNotFoundError:
        return "not known"


async def build_server(opts: ServeOptions) -> tuple[Server, StationService, str]:
    """The configured, not yet started server and its station service; the endpoint URL."""
    users = read_users(opts.users)
    cert, key, trust = _paths(opts)
    cfg = load_config(opts.config)
    server = Server(user_manager=StationUserManager(users))  # type: ignore[arg-type]
    await server.init()
    host = opts.host
    url = f"opc.tcp://{host}:{opts.port}/station/"
    server.set_endpoint(url)
    server.set_server_name(f"robot calibration station: {cfg.name}")
    await server.set_application_uri(application_uri(cert))
    await server.load_certificate(str(cert))
    await server.load_private_key(str(key))
    server.set_identity_tokens([ua.UserNameIdentityToken, ua.X509IdentityToken])  # never anonymous
    await server.set_build_info(*build_info())
    store = TrustList([trust], [])
    await store.load()
    validator = CertificateValidator(CertificateValidatorOptions.TRUSTED_VALIDATION
                                     | CertificateValidatorOptions.PEER_CLIENT, store)
    server.set_certificate_validator(validator)
    idx = await load_models(server)
    nodes = await build_instances(server, idx, cell_facts(cfg))
    request = CellRequest(config=opts.config, simulated=opts.simulated, seed=opts.seed, time_scale=opts.time_scale,
                          db=opts.db)
    service = StationService(server, nodes, request, load_cell, offset_parameters(cfg))
    server.set_security_policy(list(POLICIES), permission_ruleset=StationRuleset(service.operator_methods))
    return server, service, url


async def serve(opts: ServeOptions, stop: asyncio.Event | None = None,
                ready: Callable[[str], Awaitable[None] | None] | None = None) -> None:
    """Serve until ``stop`` is set (or SIGINT / SIGTERM); an active run is aborted at its next
    safe point and its devices closed before the server goes."""
    stop = stop or asyncio.Event()
    server, service, url = await build_server(opts)
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, stop.set)
        except (NotImplementedError, RuntimeError, ValueError):  # not the main thread (a test's server)
            pass
    async with server:
        await service.start()
        shown = url.replace("0.0.0.0", socket.gethostname())
        print(f"OPC UA server on {shown} (Basic256Sha256, Aes256_Sha256_RsaPss; Sign, SignAndEncrypt; "
              f"Ctrl-C stops)", file=sys.stderr, flush=True)
        if ready is not None:
            maybe = ready(url)
            if maybe is not None:
                await maybe
        await stop.wait()
        await service.stop()


def run(opts: ServeOptions) -> int:
    logging.getLogger("asyncua").setLevel(logging.WARNING)  # its per-request INFO lines: not the terminal's
    # the DI file declares one DataType (ns=DI;i=333) asyncua cannot classify: a known, harmless warning per start
    logging.getLogger("asyncua.common.xmlimporter").setLevel(logging.ERROR)
    # its one ERROR is a start that failed, with a traceback: the station says why itself (below)
    logging.getLogger("asyncua.server.server").setLevel(logging.CRITICAL)
    bound_logging()  # a client's oversized or repeated requests must not fill the disk through the log
    try:
        asyncio.run(serve(opts))
    except OSError as exc:
        if exc.errno in (errno.EADDRINUSE, errno.EACCES, errno.EADDRNOTAVAIL):
            raise ConfigError(f"cannot listen on {opts.host}:{opts.port} ({exc.strerror}): another server may use the "
                              f"port, or the address is not this machine's; give --port or --host") from None
        raise
    return 0
