"""Secured swarms: a certificate authority, a certificate per role, and the router's access
control, all on Zenoh's own mechanisms (SPEC §7).

``fishswarm secure init DIR`` makes, with the ``cryptography`` package:

- ``ca.pem`` / ``ca.key``: the swarm's certificate authority (keep the key off the robots);
- ``<subject>.pem`` / ``<subject>.key`` for every subject: ``router``, ``world``,
  ``channel``, ``admin``, ``observer`` (and ``observer-<name>`` for named observers),
  ``robot-<id>`` for each robot; the certificate's common name is the subject;
- ``access_control.json`` for the router: deny by default, and for each subject only the
  keys its role needs (:func:`access_control`).

A secured router listens on ``tls/`` endpoints only and asks every client for a certificate
of this authority (mutual TLS); its access control names subjects by certificate common
name. Every other process is a client with scouting off, so nothing reaches the swarm but
through the router. Zenoh's access control does not filter liveliness (zenoh issue 1562):
the world defends itself (a fish counts only when the subject it hears from may command it).
"""

from __future__ import annotations

import datetime
import ipaddress
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fishswarm.protocols.keys import KeySpace

AUTHORITY = "ca"
ACCESS_FILE = "access_control.json"
BASE_SUBJECTS = ("router", "world", "channel", "admin", "observer")
"""Subjects every secured swarm has; robots and named observers are added to them."""
DEFAULT_DAYS = 365


class SecurityError(RuntimeError):
    """A secured swarm's files are missing, expired or not of its authority; the message says
    which and how to fix it."""


def robot_subject(robot_id: int) -> str:
    """The subject (certificate common name) of robot ``robot_id``'s fish."""
    return f"robot-{robot_id}"


def observer_subject(name: str | None) -> str:
    """The subject of an observer: ``observer``, or ``observer-<name>``."""
    return "observer" if not name else f"observer-{name}"


@dataclass(frozen=True)
class Rights:
    """What one subject may do: keys it publishes, keys it subscribes to, and keys it may
    query (or serve queries on, ``serves``)."""

    publishes: tuple[str, ...] = ()
    subscribes: tuple[str, ...] = ()
    queries: tuple[str, ...] = ()
    serves: tuple[str, ...] = ()


def rights_of(subject: str, keys: KeySpace) -> Rights:
    """The rights of a subject in the swarm of ``keys``.

    Raises:
        ValueError: an unknown subject.
    """
    if subject == "world":
        return Rights(
            publishes=(
                keys.perception("*"), keys.every_school("perceptions"), keys.snapshot,
                keys.world_pulse,
            ),
            subscribes=(
                keys.command("*"), keys.every_school("commands"), keys.channel_report,
                *keys.abouts(),
            ),
            serves=(keys.control,),
        )  # fmt: skip
    if subject == "channel":
        return Rights(
            publishes=(keys.inbox("*"), keys.channel_report),
            subscribes=(keys.snapshot, keys.fish_outboxes()),
        )
    if subject == "admin":
        return Rights(
            publishes=(keys.robot_order,),
            subscribes=(keys.robot_statuses(), keys.snapshot),
            queries=(keys.control,),
        )
    if subject == "observer" or subject.startswith("observer-"):
        return Rights(subscribes=(keys.snapshot, keys.robot_statuses()))
    if subject.startswith("robot-") and subject[6:].isdigit():
        robot = int(subject[6:])
        return Rights(
            publishes=(
                keys.command(robot), keys.outbox(robot), keys.about(robot),
                keys.robot_status(robot),
            ),
            # A mock robot's body (docs/robot.md) sees the tank through the snapshots.
            subscribes=(
                keys.perception(robot), keys.inbox(robot), keys.world_pulse, keys.robot_order,
                keys.snapshot,
            ),
        )  # fmt: skip
    raise ValueError(f"unknown subject {subject!r}")


def access_control(subjects: Iterable[str], keys: KeySpace) -> dict[str, Any]:
    """The router's access control: deny by default; each subject allowed its :func:`rights_of`.

    A subscriber only receives what its subject may also ``put`` on egress (measured, SPEC
    §7), so subscribing grants both; liveliness is allowed on the swarm's ``alive`` keys (the
    access control does not filter it anyway).
    """
    rules: list[dict[str, Any]] = []
    subject_entries: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    liveliness = {
        "id": "liveliness",
        "messages": ["liveliness_token", "liveliness_query", "declare_liveliness_subscriber"],
        "flows": ["ingress", "egress"],
        "permission": "allow",
        "key_exprs": [keys.alive_all()],
    }
    rules.append(liveliness)
    for subject in subjects:
        if subject == "router":
            continue
        rights = rights_of(subject, keys)
        mine: list[str] = []
        kinds = (
            ("publish", ["put", "delete"], ["ingress"], rights.publishes),
            ("subscribe", ["declare_subscriber", "put", "delete"], ["ingress", "egress"],
             rights.subscribes),
            ("query", ["query", "reply"], ["ingress", "egress"], rights.queries),
            ("serve", ["declare_queryable", "query", "reply"], ["ingress", "egress"],
             rights.serves),
        )  # fmt: skip
        for name, messages, flows, exprs in kinds:
            if not exprs:
                continue
            rules.append(
                {
                    "id": f"{subject}-{name}",
                    "messages": messages,
                    "flows": flows,
                    "permission": "allow",
                    "key_exprs": list(exprs),
                }
            )
            mine.append(f"{subject}-{name}")
        subject_entries.append({"id": subject, "cert_common_names": [subject]})
        policies.append({"rules": [*mine, "liveliness"], "subjects": [subject]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subject_entries,
        "policies": policies,
    }


def init_secure(
    folder: Path,
    *,
    robots: Sequence[int] = (),
    observers: Sequence[str] = (),
    hosts: Sequence[str] = ("localhost", "127.0.0.1"),
    swarm: str = "default",
    days: int = DEFAULT_DAYS,
) -> list[Path]:
    """Make a secured swarm's authority, certificates and access control in ``folder``.

    Args:
        folder: where (created; existing files of the same names are replaced).
        robots: robot ids to make certificates for.
        observers: names of observers to make certificates for (besides ``observer``).
        hosts: names and addresses the router is reached by (its certificate's names).
        swarm: the swarm whose keys the access control names.
        days: how long the certificates are valid.

    Returns:
        The files written.

    Raises:
        ValueError: a bad robot id, observer name, host or number of days.
    """
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    if days < 1:
        raise ValueError(f"certificates must be valid for at least a day, got {days}")
    keys = KeySpace(swarm)
    subjects = [*BASE_SUBJECTS, *(observer_subject(n) for n in observers)]
    subjects += [robot_subject(int(r)) for r in robots]
    for subject in subjects:
        if subject != "router":
            rights_of(subject, keys)  # every subject must have a role
    names: list[x509.GeneralName] = []
    for host in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    folder.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.UTC)
    start, end = now - datetime.timedelta(minutes=5), now + datetime.timedelta(days=days)
    authority_key = ec.generate_private_key(ec.SECP256R1())
    authority_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"fishswarm {swarm}")])
    usage = dict.fromkeys(
        ("content_commitment", "key_encipherment", "data_encipherment", "key_agreement",
         "encipher_only", "decipher_only"), False,
    )  # fmt: skip
    authority = (
        x509.CertificateBuilder()
        .subject_name(authority_name)
        .issuer_name(authority_name)
        .public_key(authority_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(end)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True, **usage),
            critical=True,
        )
        .add_extension(
            x509.SubjectKeyIdentifier.from_public_key(authority_key.public_key()), critical=False
        )
        .sign(authority_key, hashes.SHA256())
    )
    written = _write(folder, AUTHORITY, authority_key, authority)
    for subject in subjects:
        key = ec.generate_private_key(ec.SECP256R1())
        certificate = (
            x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)]))
            .issuer_name(authority_name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(start)
            .not_valid_after(end)
            .add_extension(x509.SubjectAlternativeName(names), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(
                x509.ExtendedKeyUsage(
                    [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
                ),
                critical=False,
            )
            .add_extension(
                x509.AuthorityKeyIdentifier.from_issuer_public_key(authority_key.public_key()),
                critical=False,
            )
            .sign(authority_key, hashes.SHA256())
        )
        written += _write(folder, subject, key, certificate)
    access = folder / ACCESS_FILE
    access.write_text(json.dumps(access_control(subjects, keys), indent=2), encoding="utf-8")
    return [*written, access]


def _write(folder: Path, name: str, key: Any, certificate: Any) -> list[Path]:
    from cryptography.hazmat.primitives import serialization

    key_path, certificate_path = folder / f"{name}.key", folder / f"{name}.pem"
    key_path.write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    key_path.chmod(0o600)
    certificate_path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    return [certificate_path, key_path]


def check_subject(folder: Path, subject: str) -> None:
    """Check that ``folder`` holds a usable certificate of its authority for ``subject``.

    Raises:
        SecurityError: a file is missing or unreadable, the certificate is not valid now,
            names another subject, or was not signed by the folder's authority.
    """
    from cryptography import x509
    from cryptography.exceptions import InvalidSignature
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    fix = f"make them with: fishswarm secure init {folder}"
    paths = [folder / f"{AUTHORITY}.pem", folder / f"{subject}.pem", folder / f"{subject}.key"]
    for path in paths:
        if not path.is_file():
            raise SecurityError(f"{path} is missing: no certificate for {subject!r} ({fix})")
    try:
        authority = x509.load_pem_x509_certificate(paths[0].read_bytes())
        certificate = x509.load_pem_x509_certificate(paths[1].read_bytes())
    except ValueError as error:
        raise SecurityError(f"{paths[1]} or {paths[0]} is not a PEM certificate: {error}") from None
    now = datetime.datetime.now(datetime.UTC)
    for path, cert in ((paths[0], authority), (paths[1], certificate)):
        if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
            raise SecurityError(
                f"{path} is valid from {cert.not_valid_before_utc:%Y-%m-%d %H:%M} to "
                f"{cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC, not now: renew it ({fix})"
            )
    names = certificate.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    if not names or names[0].value != subject:
        found = names[0].value if names else "none"
        raise SecurityError(f"{paths[1]} is the certificate of {found!r}, not of {subject!r}")
    public = authority.public_key()
    if not isinstance(public, ec.EllipticCurvePublicKey):
        raise SecurityError(f"{paths[0]} is not a fishswarm authority (not an EC key)")
    try:
        assert certificate.signature_hash_algorithm is not None
        public.verify(
            certificate.signature,
            certificate.tbs_certificate_bytes,
            ec.ECDSA(certificate.signature_hash_algorithm),
        )
    except (InvalidSignature, AssertionError):
        raise SecurityError(
            f"{paths[1]} was not signed by the authority {paths[0]}: use the files of one "
            f"'fishswarm secure init'"
        ) from None


def session_security(folder: Path, subject: str, *, router: bool = False) -> dict[str, Any]:
    """The Zenoh settings (``SessionSettings.extra``) of a secured session of ``subject``:
    TLS only, with its certificate; for the router also mutual TLS and the access control.

    Raises:
        SecurityError: see :func:`check_subject`; the router's access control is missing.
    """
    check_subject(folder, subject)
    tls: dict[str, Any] = {"root_ca_certificate": str(folder / f"{AUTHORITY}.pem")}
    mine = {
        "private_key": str(folder / f"{subject}.key"),
        "certificate": str(folder / f"{subject}.pem"),
    }
    side = "listen" if router else "connect"
    tls |= {f"{side}_private_key": mine["private_key"], f"{side}_certificate": mine["certificate"]}
    tls["enable_mtls"] = True
    extra: dict[str, Any] = {"transport/link/tls": tls, "transport/link/protocols": ["tls"]}
    if router:
        access = folder / ACCESS_FILE
        if not access.is_file():
            raise SecurityError(
                f"{access} is missing (make it with: fishswarm secure init {folder})"
            )
        try:
            extra["access_control"] = json.loads(access.read_text(encoding="utf-8"))
        except json.JSONDecodeError as error:
            raise SecurityError(f"{access} is not valid JSON: {error}") from None
    return extra
