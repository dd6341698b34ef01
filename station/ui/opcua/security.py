"""Who may talk to the station's OPC UA server, and what they may do.

* The server's application certificate and key: ``station serve --init-pki DIR`` writes them
  (asyncua's generator, OPC 10000-6 §6.2.2 profile: RSA 2048, SHA-256, the application URI in the
  subjectAltName), or they are supplied.
* Client applications: trusted through a folder of their certificates (DER or PEM), checked on
  every CreateSession (asyncua's CertificateValidator with its TRUSTED_VALIDATION options).
* Users: a TOML file of names, roles and either a password hash (scrypt, salted: the standard
  library's ``hashlib.scrypt``) or an X.509 user certificate. No anonymous access.
* Roles: ``observer`` browses, reads and subscribes; ``operator`` may also call the station's
  methods that move the robot or change its state. :class:`StationRuleset` checks the role on
  every request, method by method for a Call.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import logging
import os
import secrets
import socket
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asyncua import ua
from asyncua.crypto.permission_rules import USER_TYPES, SimpleRoleRuleset, User, UserRole
from asyncua.ua.ua_binary import struct_from_binary
from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding
from cryptography.x509.oid import ExtendedKeyUsageOID

from station.errors import ConfigError

ROLES = ("observer", "operator")
#: scrypt's cost (RFC 7914 §2: N a power of two; 2**14, r 8, p 1 is the interactive-login figure
#: of the RFC's §2 discussion): about 16 MiB and tens of ms per check
SCRYPT_N, SCRYPT_R, SCRYPT_P = 2**14, 8, 1
SERVER_CERT = Path("own") / "cert.der"
SERVER_KEY = Path("own") / "private" / "key.pem"
TRUSTED = Path("trusted")
#: wrong passwords for one user name before it is locked out, within this window; how long it is
#: (OWASP's authentication guidance: throttle per account; 5 in a minute is far above a mistyping PLC
#: configuration's retries and far below a guessing rate: 20 in 4.5 s went through before)
MAX_FAILURES, FAILURE_WINDOW_S, LOCKOUT_S = 5, 60.0, 60.0
log = logging.getLogger(__name__)


def hash_password(password: str, *, salt: bytes | None = None) -> str:
    """``scrypt$N$r$p$salt$hash`` (base64), for the users file."""
    if not password:
        raise ConfigError("an empty password is not a password: give one")
    salt = secrets.token_bytes(16) if salt is None else salt
    digest = hashlib.scrypt(password.encode("utf-8"), salt=salt, n=SCRYPT_N, r=SCRYPT_R, p=SCRYPT_P, dklen=32)
    b64 = base64.b64encode
    return f"scrypt${SCRYPT_N}${SCRYPT_R}${SCRYPT_P}${b64(salt).decode()}${b64(digest).decode()}"


def check_password(password: str, stored: str) -> bool:
    """Whether ``password`` matches the stored ``scrypt$…`` hash (constant-time comparison)."""
    try:
        scheme, n, r, p, salt, digest = stored.split("$")
        if scheme != "scrypt":
            return False
        want = base64.b64decode(digest)
        got = hashlib.scrypt(password.encode("utf-8"), salt=base64.b64decode(salt), n=int(n), r=int(r), p=int(p),
                             dklen=len(want), maxmem=256 * 1024 * 1024)
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(got, want)


@dataclass(frozen=True)
class Account:
    name: str
    role: str
    password_hash: str = ""
    certificate_der: bytes = b""


@dataclass
class StationUser(User):
    """asyncua's user (role User: never an administrator of the address space) with the station's role."""

    station_role: str = "observer"


@dataclass(frozen=True)
class Users:
    """The users file, read once at start."""

    accounts: tuple[Account, ...]
    source: str = ""

    def by_password(self, name: str, password: str) -> Account | None:
        for a in self.accounts:
            if a.name == name and a.password_hash:
                return a if check_password(password, a.password_hash) else None
        # the same work whether or not the name exists: no timing hint of valid names
        check_password(password, _DUMMY_HASH)
        return None

    def by_certificate(self, der: bytes) -> Account | None:
        return next((a for a in self.accounts if a.certificate_der and hmac.compare_digest(a.certificate_der, der)), None)


_DUMMY_HASH = hash_password("not a password", salt=b"\0" * 16)


def read_users(path: str | Path) -> Users:
    """The users file: ``[[user]]`` tables with ``name``, ``role`` (observer | operator) and
    ``password`` (a hash from ``station serve --add-user``) or ``certificate`` (a user
    certificate's file, relative to the users file). A mistake is a :class:`ConfigError` naming it."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"no such users file: {path}; create it with 'station serve --users {path} --add-user "
                          f"NAME --role operator'") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None
    accounts = []
    for i, entry in enumerate(data.get("user", [])):
        where = f"{path}: [[user]] {i + 1}"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where}: expected a table")
        name, role = entry.get("name"), entry.get("role")
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{where}: give its name = \"…\"")
        if role not in ROLES:
            raise ConfigError(f"{where} ({name}): role must be one of {', '.join(ROLES)}, got {role!r}")
        pw, cert = entry.get("password", ""), entry.get("certificate", "")
        if bool(pw) == bool(cert):
            raise ConfigError(f"{where} ({name}): give either password (a hash from 'station serve --add-user') or "
                              f"certificate (a user certificate file), one of them")
        if pw and not (isinstance(pw, str) and pw.startswith("scrypt$") and len(pw.split("$")) == 6):
            raise ConfigError(f"{where} ({name}): password must be a scrypt hash written by 'station serve --add-user', "
                              f"never the password itself")
        der = b""
        if cert:
            der = certificate_der(path.parent / str(cert))
        accounts.append(Account(name, role, pw, der))
    if not accounts:
        raise ConfigError(f"{path}: no [[user]]: nobody could connect (anonymous access is off); add one with "
                          f"'station serve --users {path} --add-user NAME --role operator'")
    return Users(tuple(accounts), str(path))


def certificate_der(path: Path) -> bytes:
    """A certificate file (DER or PEM) as DER bytes."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"no such certificate file: {path}") from None
    try:
        cert = x509.load_pem_x509_certificate(data) if data.lstrip().startswith(b"-----") else x509.load_der_x509_certificate(data)
    except ValueError as exc:
        raise ConfigError(f"{path}: not a certificate in DER or PEM ({exc})") from None
    return cert.public_bytes(Encoding.DER)


def add_user(path: str | Path, name: str, role: str, password: str) -> None:
    """Append a password user to the users file (created if missing); a name already there is refused."""
    path = Path(path)
    if role not in ROLES:
        raise ConfigError(f"--role {role}: give one of {', '.join(ROLES)}")
    # TOML's basic strings take no control character (TOML 1.0 "Basic strings"): one written
    # there made the file unreadable for the server and every later --add-user
    if not name or any(c in name for c in "\"\\") or any(not c.isprintable() for c in name):
        raise ConfigError(f"--add-user {name!r}: give a plain user name (printable characters, no quote or "
                          f"backslash); nothing was written")
    text = path.read_text(encoding="utf-8") if path.exists() else (
        "# Users of 'station serve --opcua' (docs/opcua.md): password hashes (scrypt), never passwords\n")
    if path.exists() and any(a.name == name for a in read_users(path).accounts):
        raise ConfigError(f"{path}: a user {name!r} exists already; remove its [[user]] table first")
    text += f'\n[[user]]\nname = "{name}"\nrole = "{role}"\npassword = "{hash_password(password)}"\n'
    write_secret(path, text.encode("utf-8"))


def write_secret(path: Path, data: bytes) -> None:
    """Replace ``path`` with ``data`` through a file that is mode 600 from its creation (never
    readable by others, not for an instant: write then chmod left a window), renamed over it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o600)  # the umask can only remove bits; this keeps it 600 whatever the umask
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


class StationUserManager:
    """asyncua's user manager over the users file: a user name with its password, or a user
    certificate; None (BadUserAccessDenied) for anything else, anonymous included."""

    def __init__(self, users: Users, clock: Callable[[], float] = time.monotonic) -> None:
        self.users = users
        self.clock = clock
        self._failures: dict[str, list[float]] = {}  # user name -> times of its recent wrong passwords
        self._locked: dict[str, float] = {}  # user name -> when its lockout ends

    def locked(self, name: str) -> bool:
        """Whether ``name`` is locked out now (after :data:`MAX_FAILURES` wrong passwords within
        :data:`FAILURE_WINDOW_S`): every password is refused until :data:`LOCKOUT_S` have passed."""
        until = self._locked.get(name)
        if until is not None and self.clock() >= until:
            del self._locked[name]
            until = None
        return until is not None

    def _failed(self, name: str) -> None:
        now = self.clock()
        recent = [t for t in self._failures.get(name, []) if now - t < FAILURE_WINDOW_S] + [now]
        self._failures[name] = recent
        if len(recent) >= MAX_FAILURES:
            self._locked[name] = now + LOCKOUT_S
            self._failures.pop(name)
            log.warning("user %r: %d wrong passwords within %.0f s, refused for %.0f s", name[:64], len(recent),
                        FAILURE_WINDOW_S, LOCKOUT_S)
        while len(self._failures) > 10_000:  # unknown names must not grow the table without bound
            self._failures.pop(next(iter(self._failures)))

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> User | None:
        account = None
        if username is not None:
            if self.locked(username):
                return None
            account = self.users.by_password(username, password or "")
            if account is None:
                self._failed(username)
        elif certificate is not None:
            account = self.users.by_certificate(bytes(certificate))
        if account is None:
            return None
        return StationUser(role=UserRole.User, name=account.name, station_role=account.role)


class StationRuleset(SimpleRoleRuleset):
    """The role on every request: both roles browse, read and subscribe; nobody writes or changes
    the address space; a Call is allowed to an observer only when none of its methods is in
    ``operator_methods`` (the station's start, abort and acknowledge)."""

    def __init__(self, operator_methods: set[ua.NodeId]) -> None:
        super().__init__()
        self.operator_methods = operator_methods
        write = ua.NodeId(ua.Int32(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary))
        self._allowed = {ua.NodeId(ua.Int32(t)) for t in USER_TYPES} - {write}
        self._call = ua.NodeId(ua.Int32(ua.ObjectIds.CallRequest_Encoding_DefaultBinary))

    def check_validity(self, user: Any, action_type_id: ua.NodeId, body: Any) -> bool:
        role = getattr(user, "station_role", None)
        if role not in ROLES or action_type_id not in self._allowed:
            return False
        if action_type_id == self._call and role != "operator":
            calls = _methods_to_call(body)
            return calls is not None and not any(c.MethodId in self.operator_methods for c in calls)
        return True


def _methods_to_call(body: Any) -> list[Any] | None:
    """The methods a Call request names; None when the body cannot be decoded (then the caller is
    refused: the safe side). asyncua hands the ruleset the request's undecoded body (its Buffer,
    decoded after the check): decode a copy, leave the original for the call."""
    try:
        params = struct_from_binary(ua.CallParameters, body.copy() if hasattr(body, "copy") else body)
    except Exception:  # noqa: BLE001 - see above
        return None
    return list(params.MethodsToCall or [])


def init_pki(directory: str | Path, application_uri: str, host: str | None = None, days: int = 825) -> Path:
    """``station serve --init-pki DIR``: the server's key and self-signed application
    certificate (DIR/own/), and the empty trust list (DIR/trusted/) the client certificates go
    in. An existing key is never overwritten. Returns the certificate's path."""
    directory = Path(directory)
    cert_path, key_path = directory / SERVER_CERT, directory / SERVER_KEY
    if key_path.exists():
        raise ConfigError(f"{key_path} exists already: the station keeps its key; remove DIR/own to make a new one")
    make_certificate(cert_path, key_path, application_uri, host or socket.gethostname(), server=True, days=days)
    (directory / TRUSTED).mkdir(parents=True, exist_ok=True)
    return cert_path


def make_certificate(cert_path: Path, key_path: Path, application_uri: str, host: str, *, server: bool,
                     days: int = 825, common_name: str = "") -> None:
    """A key (PEM, mode 600) and a self-signed OPC UA application certificate (DER) for a server
    or a client (a client: the line's PLC, a test; a user certificate is a client one too)."""
    from asyncua.crypto import cert_gen

    key = cert_gen.generate_private_key()
    names = [x509.UniformResourceIdentifier(application_uri), x509.DNSName(host)]
    use = [ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH]
    cert = cert_gen.generate_self_signed_app_certificate(key, common_name or application_uri, {}, names, use,
                                                         days=days)
    key_path.parent.mkdir(parents=True, exist_ok=True)
    cert_path.parent.mkdir(parents=True, exist_ok=True)
    write_secret(key_path, cert_gen.dump_private_key_as_pem(key))
    cert_path.write_bytes(cert.public_bytes(Encoding.DER))
