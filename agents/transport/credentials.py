"""A fleet's identities and its secure Zenoh configurations: ``evopose fleet credentials`` (docs/security.md).

:func:`create_credentials` writes into one directory:

- ``ca.pem``, ``ca.key``: the fleet's certificate authority (keep ``ca.key`` offline once the fleet is set up;
  it is needed only to issue more certificates and is never given to a vehicle or the router);
- ``router.pem``, ``router.key``: the router's certificate, for ``127.0.0.1``, ``localhost`` and each
  ``router_hosts`` name or address (clients check it: ``verify_name_on_connect``);
- ``<vehicle>.pem``, ``<vehicle>.key`` per vehicle (and per observer): a client certificate whose common
  name is the vehicle's name. Zenoh's ACL matches that name (``cert_common_names``), so a vehicle's
  identity is its certificate, never a field it fills in;
- ``router.json5``: a Zenoh router listening with TLS only, mutual TLS required, multicast scouting off,
  and a deny-by-default access control list (:func:`router_acl`);
- ``<vehicle>.json5``: a Zenoh client connecting to the router with TLS, its own certificate and the CA.

Keys are ECDSA P-256 in PKCS#8 PEM (rustls, which Zenoh uses, reads PKCS#8, SEC1 and PKCS#1), written with
mode 0600. Paths inside the configurations are file names relative to the configuration's directory;
:func:`agents.transport.session.make_config` resolves them against the file's directory, so the directory
can be moved or mounted anywhere (plain ``zenohd`` resolves them against its working directory instead).

Zenoh configuration keys used (Zenoh 1.x, DEFAULT_CONFIG.json5): ``mode``, ``listen/endpoints``,
``connect/endpoints``, ``scouting/multicast/enabled``, ``transport/link/protocols``,
``transport/link/tls/{root_ca_certificate, listen_private_key, listen_certificate, enable_mtls,
connect_private_key, connect_certificate, verify_name_on_connect}`` and
``access_control/{enabled, default_permission, rules, subjects, policies}`` with rules of
``{id, messages, flows, permission, key_exprs}`` and subjects of ``{id, cert_common_names}``.
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from protocol import check_name
from protocol.keys import ALIVE, ROOT

from agents.errors import FleetError

#: Where the router listens and the vehicles connect, unless told otherwise.
DEFAULT_ROUTER_ENDPOINT = "tls/127.0.0.1:7447"
#: Names the router certificate is always valid for (a fleet on one host).
LOOPBACK_HOSTS = ("127.0.0.1", "localhost")
#: Addresses that mean "every interface": never a name to connect to.
WILDCARDS = ("0.0.0.0", "::")
#: Common name of the router's certificate: not a valid vehicle name (``@``), so it never matches a vehicle.
ROUTER_COMMON_NAME = "@router"
#: Validity of the certificates.
DEFAULT_DAYS = 365
#: Files of the directory that are not per vehicle.
CA_CERT, CA_KEY, ROUTER = "ca.pem", "ca.key", "router"


class CredentialsError(FleetError):
    """Bad arguments for the credentials, or a directory that cannot hold them."""


@dataclass(frozen=True)
class FleetCredentials:
    """What :func:`create_credentials` wrote (absolute paths)."""

    directory: Path
    fleet: str
    vehicles: tuple[str, ...]
    observers: tuple[str, ...]
    router_endpoint: str
    router_hosts: tuple[str, ...]

    @property
    def ca_certificate(self) -> Path:
        return self.directory / CA_CERT

    @property
    def router_config(self) -> Path:
        return self.directory / f"{ROUTER}.json5"

    def config(self, member: str) -> Path:
        """The client configuration of a vehicle or observer."""
        if member not in self.vehicles and member not in self.observers:
            raise CredentialsError(f"{member!r} is not a member of fleet {self.fleet!r}")
        return self.directory / f"{member}.json5"

    def as_dict(self) -> dict:
        return {"directory": str(self.directory), "fleet": self.fleet, "vehicles": list(self.vehicles),
                "observers": list(self.observers), "router_endpoint": self.router_endpoint,
                "router_hosts": list(self.router_hosts), "router_config": str(self.router_config),
                "configs": {m: str(self.config(m)) for m in (*self.vehicles, *self.observers)}}


# -- the access control list -------------------------------------------------------------------------

def fleet_keys(fleet: str) -> tuple[str, str]:
    """``(data, presence)`` key expressions of a fleet: ``evopose/<fleet>/**`` and ``evopose/<fleet>/@alive/*``.

    Two, because a chunk starting with ``@`` is verbatim in Zenoh: ``**`` never matches ``@alive``.
    """
    return f"{ROOT}/{fleet}/**", f"{ROOT}/{fleet}/{ALIVE}/*"


def router_acl(fleet: str, vehicles: Sequence[str], observers: Sequence[str] = ()) -> dict:
    """Zenoh's ``access_control`` section: deny by default; per certificate common name what it may do.

    - vehicle V may put (and delete) only under ``evopose/<fleet>/V/**`` and declare only its own
      liveliness token ``evopose/<fleet>/@alive/V`` (ingress, i.e. what the router accepts from V);
    - every member (vehicles and observers) may subscribe to the fleet's data and presence and query
      presence (ingress), and is sent the fleet's data, subscriptions and tokens (egress);
    - observers may put nothing and declare no token.

    Anything else, from anyone (a client without a certificate cannot even connect), is dropped.
    """
    data, presence = fleet_keys(fleet)
    members = [*vehicles, *observers]
    rules = [
        {"id": "member-subscribe", "messages": ["declare_subscriber"], "flows": ["ingress"], "permission": "allow",
         "key_exprs": [data]},
        {"id": "member-presence", "messages": ["declare_liveliness_subscriber", "liveliness_query"],
         "flows": ["ingress"], "permission": "allow", "key_exprs": [presence]},
        {"id": "member-receive", "messages": ["put", "delete", "declare_subscriber"], "flows": ["egress"],
         "permission": "allow", "key_exprs": [data]},
        {"id": "member-receive-presence",
         "messages": ["liveliness_token", "declare_liveliness_subscriber", "liveliness_query"], "flows": ["egress"],
         "permission": "allow", "key_exprs": [presence]},
    ]
    subjects = [{"id": "members", "cert_common_names": members}]
    policies = [{"id": "members", "rules": [r["id"] for r in rules], "subjects": ["members"]}]
    for vehicle in vehicles:
        rule_ids = [f"publish-{vehicle}", f"presence-{vehicle}"]
        rules += [
            {"id": rule_ids[0], "messages": ["put", "delete"], "flows": ["ingress"], "permission": "allow",
             "key_exprs": [f"{ROOT}/{fleet}/{vehicle}/**"]},
            {"id": rule_ids[1], "messages": ["liveliness_token"], "flows": ["ingress"], "permission": "allow",
             "key_exprs": [f"{ROOT}/{fleet}/{ALIVE}/{vehicle}"]},
        ]
        subjects.append({"id": f"vehicle-{vehicle}", "cert_common_names": [vehicle]})
        policies.append({"id": f"vehicle-{vehicle}", "rules": rule_ids, "subjects": [f"vehicle-{vehicle}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def router_config(fleet: str, vehicles: Sequence[str], observers: Sequence[str] = (), *,
                  listen: str = DEFAULT_ROUTER_ENDPOINT) -> dict:
    """The router's Zenoh configuration (file names relative to its directory)."""
    return {
        "mode": "router",
        "listen": {"endpoints": [listen]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"protocols": ["tls"], "tls": {
            "root_ca_certificate": CA_CERT,
            "listen_private_key": f"{ROUTER}.key",
            "listen_certificate": f"{ROUTER}.pem",
            "enable_mtls": True,
        }}},
        "access_control": router_acl(fleet, vehicles, observers),
    }


def client_config(member: str, *, connect: str = DEFAULT_ROUTER_ENDPOINT) -> dict:
    """A vehicle's (or observer's) Zenoh configuration: a TLS client of the router."""
    return {
        "mode": "client",
        "connect": {"endpoints": [connect]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"protocols": ["tls"], "tls": {
            "root_ca_certificate": CA_CERT,
            "connect_private_key": f"{member}.key",
            "connect_certificate": f"{member}.pem",
            "enable_mtls": True,  # on a client: present the certificate (Zenoh loads the connect_* files only then)
            "verify_name_on_connect": True,
        }}},
    }


# -- certificates ------------------------------------------------------------------------------------

def _new_key() -> ec.EllipticCurvePrivateKey:
    return ec.generate_private_key(ec.SECP256R1())


def _name(common_name: str, fleet: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, f"evopose fleet {fleet}"),
                      x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _san(hosts: Sequence[str]) -> x509.SubjectAlternativeName:
    names: list[x509.GeneralName] = []
    for host in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return x509.SubjectAlternativeName(names)


def _certificate(subject: x509.Name, public_key, issuer: x509.Name, issuer_key: ec.EllipticCurvePrivateKey, *,
                 days: int, ca: bool, usage: x509.ObjectIdentifier | None = None,
                 hosts: Sequence[str] = ()) -> x509.Certificate:
    now = datetime.datetime.now(datetime.timezone.utc)
    builder = (x509.CertificateBuilder().subject_name(subject).issuer_name(issuer).public_key(public_key)
               .serial_number(x509.random_serial_number())
               .not_valid_before(now - datetime.timedelta(minutes=5))
               .not_valid_after(now + datetime.timedelta(days=days))
               .add_extension(x509.BasicConstraints(ca=ca, path_length=0 if ca else None), critical=True)
               .add_extension(x509.SubjectKeyIdentifier.from_public_key(public_key), critical=False))
    if ca:
        builder = builder.add_extension(x509.KeyUsage(
            digital_signature=True, content_commitment=False, key_encipherment=False, data_encipherment=False,
            key_agreement=False, key_cert_sign=True, crl_sign=True, encipher_only=False, decipher_only=False),
            critical=True)
    else:
        builder = (builder
                   .add_extension(x509.KeyUsage(
                       digital_signature=True, content_commitment=False, key_encipherment=False,
                       data_encipherment=False, key_agreement=False, key_cert_sign=False, crl_sign=False,
                       encipher_only=False, decipher_only=False), critical=True)
                   .add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
                   .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(issuer_key.public_key()),
                                  critical=False))
        if hosts:
            builder = builder.add_extension(_san(hosts), critical=False)
    return builder.sign(issuer_key, hashes.SHA256())


def _write(path: Path, data: bytes, mode: int) -> None:
    """Write ``data`` to ``path`` created with ``mode`` (never readable by others, even for a moment)."""
    if path.is_symlink():
        path.unlink()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
    try:
        os.fchmod(fd, mode)
        os.write(fd, data)
    finally:
        os.close(fd)


def _write_key(path: Path, key: ec.EllipticCurvePrivateKey) -> None:
    _write(path, key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                   serialization.NoEncryption()), 0o600)


def _write_cert(path: Path, cert: x509.Certificate) -> None:
    _write(path, cert.public_bytes(serialization.Encoding.PEM), 0o644)


def _write_json5(path: Path, header: str, document: dict) -> None:
    # JSON is valid JSON5; the comment says where the file came from
    _write(path, (f"// {header}\n" + json.dumps(document, indent=2) + "\n").encode(), 0o644)


def _endpoint_host(endpoint: str) -> str:
    address = endpoint.split("/", 1)[1].split("#")[0].split("?")[0]
    host = address.rsplit(":", 1)[0]
    return host.strip("[]")


def check_member_names(fleet: str, vehicles: Sequence[str], observers: Sequence[str] = ()) -> None:
    check_name(fleet, "fleet")
    if not vehicles:
        raise CredentialsError("--vehicles must name at least one vehicle")
    seen: set[str] = set()
    for name in (*vehicles, *observers):
        check_name(name, "vehicle")
        if name in seen:
            raise CredentialsError(f"{name!r} is named twice")
        if name.lower() in (ROUTER, CA_CERT.split(".")[0]):
            raise CredentialsError(f"{name!r} is reserved for the router's and the CA's files; choose another name")
        seen.add(name)


def create_credentials(directory: Path | str, fleet: str, vehicles: Sequence[str], *,
                       observers: Sequence[str] = (), router_hosts: Sequence[str] = (),
                       listen: str = DEFAULT_ROUTER_ENDPOINT, connect: str | None = None, days: int = DEFAULT_DAYS,
                       overwrite: bool = False) -> FleetCredentials:
    """Create a fleet CA, the router's and each member's certificate and key, and their Zenoh configurations.

    Parameters
    ----------
    directory : Path
        Created if needed (mode 0700); existing credentials there are refused unless ``overwrite``.
    fleet : str
        The fleet name of the ACL's key expressions.
    vehicles, observers : sequence of str
        Members: vehicles may publish under their own keys; observers (e.g. a meter) only receive.
    router_hosts : sequence of str
        More names or addresses the router is reached at (its certificate's subject alternative names).
    listen : str
        The router's TLS endpoint.
    connect : str or None
        Where the clients connect (default: ``listen``, with a wildcard address replaced by 127.0.0.1).
    days : int
        Validity of the certificates.
    """
    vehicles, observers = tuple(vehicles), tuple(observers)
    check_member_names(fleet, vehicles, observers)
    for endpoint, what in ((listen, "listen"), (connect, "connect")):
        if endpoint is not None and not endpoint.startswith("tls/"):
            raise CredentialsError(f"the router's {what} endpoint must be a tls/ endpoint, got {endpoint!r}")
    if days < 1:
        raise CredentialsError(f"--days must be at least 1, got {days}")
    if connect is None:  # the router's own endpoint; a wildcard address is reached on loopback
        port = listen.split("#")[0].split("?")[0].rsplit(":", 1)[1]
        connect = listen if _endpoint_host(listen) not in WILDCARDS else f"tls/127.0.0.1:{port}"
    hosts = tuple(h for h in dict.fromkeys((*LOOPBACK_HOSTS, *router_hosts, _endpoint_host(connect)))
                  if h not in WILDCARDS)

    directory = Path(directory).absolute()
    if directory.exists() and not directory.is_dir():
        raise CredentialsError(f"{str(directory)!r} exists and is not a directory")
    directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    if not overwrite and (directory / CA_CERT).exists():
        raise CredentialsError(f"{str(directory)!r} already holds credentials ({CA_CERT}); choose another directory "
                               "or give --force to replace them")

    ca_key = _new_key()
    ca_name = _name(f"evopose fleet {fleet} CA", fleet)
    ca_cert = _certificate(ca_name, ca_key.public_key(), ca_name, ca_key, days=days, ca=True)
    _write_key(directory / CA_KEY, ca_key)
    _write_cert(directory / CA_CERT, ca_cert)

    router_key = _new_key()
    _write_key(directory / f"{ROUTER}.key", router_key)
    _write_cert(directory / f"{ROUTER}.pem",
                _certificate(_name(ROUTER_COMMON_NAME, fleet), router_key.public_key(), ca_name, ca_key, days=days,
                             ca=False, usage=ExtendedKeyUsageOID.SERVER_AUTH, hosts=hosts))
    for member in (*vehicles, *observers):
        key = _new_key()
        _write_key(directory / f"{member}.key", key)
        _write_cert(directory / f"{member}.pem",
                    _certificate(_name(member, fleet), key.public_key(), ca_name, ca_key, days=days, ca=False,
                                 usage=ExtendedKeyUsageOID.CLIENT_AUTH))
        role = "vehicle" if member in vehicles else "observer"
        _write_json5(directory / f"{member}.json5",
                     f"evopose fleet {fleet}: {role} {member}, a TLS client of the router (evopose fleet credentials)",
                     client_config(member, connect=connect))
    _write_json5(directory / f"{ROUTER}.json5",
                 f"evopose fleet {fleet}: the router, mTLS and a deny-by-default ACL (evopose fleet credentials)",
                 router_config(fleet, vehicles, observers, listen=listen))
    return FleetCredentials(directory, fleet, vehicles, observers, connect, hosts)


__all__ = ["CredentialsError", "DEFAULT_ROUTER_ENDPOINT", "FleetCredentials", "client_config", "create_credentials",
           "fleet_keys", "router_acl", "router_config"]
