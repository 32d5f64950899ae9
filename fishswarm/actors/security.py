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
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fishswarm.protocols.checks import check_int
from fishswarm.protocols.hosts import host_address
from fishswarm.protocols.keys import MAX_FISH_ID, KeySpace, check_name

AUTHORITY = "ca"
ACCESS_FILE = "access_control.json"
BASE_SUBJECTS = ("router", "world", "channel", "admin", "observer")
"""Subjects every secured swarm has; robots and named observers are added to them."""
DEFAULT_DAYS = 365
MAX_DAYS = 36_500
"""Certificates last at most a hundred years (dates past 9999 cannot be written)."""


class SecurityError(RuntimeError):
    """A secured swarm's files are missing, expired or not of its authority; the message says
    which and how to fix it."""


def _require_cryptography() -> None:
    """Raise SecurityError, with how to install it, if the ``cryptography`` package that
    makes and checks certificates is missing."""
    try:
        import cryptography  # noqa: F401
    except ModuleNotFoundError:
        raise SecurityError(
            "a secured swarm's certificates need the cryptography package: pip install -e "
            "'.[secure]' (on a robot: apt install python3-cryptography; deploy/ does)"
        ) from None


def robot_subject(robot_id: int) -> str:
    """The subject (certificate common name) of robot ``robot_id``'s fish."""
    return f"robot-{robot_id}"


def observer_subject(name: str | None) -> str:
    """The subject of an observer: ``observer``, or ``observer-<name>``."""
    return "observer" if not name else f"observer-{name}"


@dataclass(frozen=True)
class Rights:
    """What one subject may do: keys it publishes, keys it subscribes to, and keys it may
    query (or serve queries on, ``serves``); a subscription it may declare wide
    (``declares``) while it receives only some of the keys under it (``receives``)."""

    publishes: tuple[str, ...] = ()
    subscribes: tuple[str, ...] = ()
    queries: tuple[str, ...] = ()
    serves: tuple[str, ...] = ()
    declares: tuple[str, ...] = ()
    receives: tuple[str, ...] = ()


def school_subject(school: str) -> str:
    """The subject of a school's worker process (``run --secure`` signs one per run)."""
    return f"school-{school}"


def school_rights(keys: KeySpace, school: str, fish_ids: Sequence[int]) -> Rights:
    """The rights of a school's worker: its school's keys and its fish's outboxes out; its
    school's perceptions, the pulse and its own fish's deliveries in (it subscribes to every
    fish's inbox at once, and the router passes it only its own: SPEC §7's egress rule)."""
    return Rights(
        publishes=(
            keys.school_commands(school), keys.about(fish_ids[0], school),
            *(keys.outbox(fish_id) for fish_id in fish_ids),
        ),
        subscribes=(keys.school_perceptions(school), keys.world_pulse),
        declares=(keys.fish_inboxes(),),
        receives=tuple(keys.inbox(fish_id) for fish_id in fish_ids),
    )  # fmt: skip


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
            serves=(keys.control, keys.scenario),
        )  # fmt: skip
    if subject == "channel":
        return Rights(
            publishes=(keys.inbox("*"), keys.channel_report),
            subscribes=(keys.snapshot, keys.fish_outboxes()),
            queries=(keys.scenario,),  # each run's medium, from its world
        )
    if subject == "admin":
        return Rights(
            publishes=(keys.robot_order,),
            subscribes=(keys.robot_statuses(), keys.snapshot),
            queries=(keys.control, keys.scenario),
        )
    if subject == "observer" or subject.startswith("observer-"):
        # The pulse tells an observer whether its run ended or its world was lost.
        return Rights(
            subscribes=(keys.snapshot, keys.robot_statuses(), keys.world_pulse),
            queries=(keys.scenario,),
        )
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


def access_control(
    subjects: Iterable[str], keys: KeySpace, schools: Mapping[str, Sequence[int]] | None = None
) -> dict[str, Any]:
    """The router's access control: deny by default; each subject allowed its
    :func:`rights_of`, and each school (name → its fish ids) its :func:`school_rights`.

    A subscriber only receives what its subject may also ``put`` on egress (measured, SPEC
    §7), so subscribing grants that too, on egress only: from the subject to the router a put
    needs the right to publish. Liveliness is allowed on the swarm's ``alive`` keys (the access
    control does not filter it anyway).
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
    granted = [(s, rights_of(s, keys)) for s in subjects if s != "router"]
    granted += [
        (school_subject(school), school_rights(keys, school, ids))
        for school, ids in (schools or {}).items()
    ]
    for subject, rights in granted:
        mine: list[str] = []
        kinds = (
            ("publish", ["put", "delete"], ["ingress"], rights.publishes),
            ("subscribe", ["declare_subscriber"], ["ingress", "egress"], rights.subscribes),
            ("query", ["query", "reply"], ["ingress", "egress"], rights.queries),
            ("serve", ["declare_queryable", "query", "reply"], ["ingress", "egress"],
             rights.serves),
            ("declare", ["declare_subscriber"], ["ingress"], rights.declares),
            ("receive", ["put", "delete"], ["egress"],
             tuple(dict.fromkeys((*rights.subscribes, *rights.receives)))),
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
    replace: bool = False,
) -> list[Path]:
    """Make a secured swarm's authority, certificates and access control in ``folder``; or,
    where ``folder`` already holds an authority, add to it: certificates for the subjects
    that have none yet, signed by it (those given out stay valid), and the access control
    rewritten for every subject with a certificate there.

    Args:
        folder: where (created).
        robots: robot ids to make certificates for.
        observers: names of observers to make certificates for (besides ``observer``).
        hosts: names and addresses the router is reached by (its certificate's names).
        swarm: the swarm whose keys the access control names.
        days: how long the certificates are valid.
        replace: make a new authority even where ``folder`` holds one. Whenever a new
            authority is made, the subjects' certificates and keys already in ``folder``
            are removed (another authority signed them, so they would be refused).

    Returns:
        The files written.

    Raises:
        ValueError: a bad robot id, observer name, host or number of days.
        SecurityError: ``folder`` holds half an authority (its certificate or its key
            alone), or one that cannot be read.
    """
    _require_cryptography()
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    if not 1 <= days <= MAX_DAYS:
        raise ValueError(f"certificates must be valid for 1 to {MAX_DAYS} days, got {days}")
    keys = KeySpace(swarm)
    for robot in robots:
        check_int("robot id", robot, high=MAX_FISH_ID)
    subjects = [*BASE_SUBJECTS, *(observer_subject(check_name("observer", n)) for n in observers)]
    # Named twice is made once: the router refuses access control with a rule twice.
    subjects = list(dict.fromkeys([*subjects, *(robot_subject(int(r)) for r in robots)]))
    for subject in subjects:
        if subject != "router":
            rights_of(subject, keys)  # every subject must have a role
    names: list[x509.GeneralName] = []
    for host in dict.fromkeys(hosts):
        address = host_address(host)
        names.append(x509.DNSName(host) if address is None else x509.IPAddress(address))
    folder.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.UTC)
    start, end = now - datetime.timedelta(minutes=5), now + datetime.timedelta(days=days)
    parts = [(folder / f"{AUTHORITY}{suffix}").is_file() for suffix in (".pem", ".key")]
    if any(parts) and not replace:
        if not all(parts):
            raise SecurityError(
                f"{folder} holds half an authority ({AUTHORITY}.pem or {AUTHORITY}.key alone): "
                "put the missing file back, or make a new authority with --force (the "
                "certificates already given out then stop being accepted)"
            )
        authority_key, authority = _load_authority(folder)
        theirs = _swarm_of(authority)
        if theirs != swarm:
            raise SecurityError(
                f"{folder}'s authority is of swarm {theirs!r}, not {swarm!r}: give --swarm "
                f"{theirs} to add to it, or --force to make a new authority"
            )
        held = certified_subjects(folder, keys)
        everyone = [*subjects, *(subject for subject in held if subject not in subjects)]
        end = min(end, authority.not_valid_after_utc)
        written: list[Path] = []
        for subject in subjects:
            if subject not in held:
                written += _issue(
                    folder, subject, authority_key, authority.subject, names, start, end
                )
        if "router" in held:
            # A host asked for that the router's certificate does not name: clients that
            # reach the router by it would be refused. Renewed under the same authority
            # (its old names kept), so nothing given out changes.
            named = _names_of(folder / "router.pem")
            if any(name not in named for name in names):
                wanted = [*named, *(name for name in names if name not in named)]
                written += _issue(
                    folder, "router", authority_key, authority.subject, wanted, start, end
                )
        access = folder / ACCESS_FILE
        access.write_text(json.dumps(access_control(everyone, keys), indent=2), encoding="utf-8")
        return [*written, access]
    # A new authority: certificates already in the folder (of an old authority, replaced
    # or lost) would only be refused later, with a message about a signature, so they go.
    for subject in certified_subjects(folder, keys):
        for suffix in (".pem", ".key"):
            (folder / f"{subject}{suffix}").unlink()
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
        written += _issue(folder, subject, authority_key, authority_name, names, start, end)
    access = folder / ACCESS_FILE
    access.write_text(json.dumps(access_control(subjects, keys), indent=2), encoding="utf-8")
    return [*written, access]


def certified_subjects(folder: Path, keys: KeySpace) -> list[str]:
    """The subjects of the swarm of ``keys`` that ``folder`` holds a certificate and key for
    (other files there are not counted)."""
    held = []
    for path in sorted(folder.glob("*.pem")):
        if path.stem == AUTHORITY or not path.with_suffix(".key").is_file():
            continue
        try:
            if path.stem != "router":
                rights_of(path.stem, keys)
        except ValueError:
            continue
        held.append(path.stem)
    return held


def router_names(folder: Path) -> list[str]:
    """The hosts and addresses the router's certificate in ``folder`` is valid for (none
    without one)."""
    _require_cryptography()
    path = folder / "router.pem"
    if not path.is_file():
        return []
    return [str(name.value) for name in _names_of(path)]


def _names_of(path: Path) -> list[Any]:
    """The names (hosts and addresses) a certificate is valid for."""
    from cryptography import x509

    certificate = x509.load_pem_x509_certificate(path.read_bytes())
    try:
        extension = certificate.extensions.get_extension_for_class(x509.SubjectAlternativeName)
    except x509.ExtensionNotFound:
        return []
    return list(extension.value)


def _issue(
    folder: Path,
    subject: str,
    authority_key: Any,
    authority_name: Any,
    names: Sequence[Any],
    start: datetime.datetime,
    end: datetime.datetime,
) -> list[Path]:
    """Write a certificate and key for ``subject`` signed by the authority, for client and
    server use under ``names``."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    certificate = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)]))
        .issuer_name(authority_name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start)
        .not_valid_after(end)
        .add_extension(x509.SubjectAlternativeName(list(names)), critical=False)
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
    return _write(folder, subject, key, certificate)


def issue_for_run(folder: Path, subjects: Sequence[str], out: Path, *, hours: float = 48.0) -> None:
    """Sign short-lived certificates for ``subjects`` with the authority of ``folder`` into
    ``out`` (with a copy of the authority's certificate): what ``run --secure`` gives its
    worker processes.

    Raises:
        SecurityError: the authority's key or certificate is missing or unreadable.
    """
    _require_cryptography()
    from cryptography import x509

    for path in (folder / f"{AUTHORITY}.key", folder / f"{AUTHORITY}.pem"):
        if not path.is_file():
            raise SecurityError(
                f"{path} is missing: a secured run signs certificates for its worker "
                "processes with the authority's key (run it where 'fishswarm secure init' "
                "wrote its files)"
            )
    authority_key, authority = _load_authority(folder)
    certificate_path = folder / f"{AUTHORITY}.pem"
    now = datetime.datetime.now(datetime.UTC)
    start, end = now - datetime.timedelta(minutes=5), now + datetime.timedelta(hours=hours)
    names = [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{AUTHORITY}.pem").write_bytes(certificate_path.read_bytes())
    for subject in subjects:
        _issue(out, subject, authority_key, authority.subject, names, start, end)


def _load_authority(folder: Path) -> tuple[Any, Any]:
    """The key and certificate of the authority in ``folder``.

    Raises:
        SecurityError: either cannot be read.
    """
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    key_path, certificate_path = folder / f"{AUTHORITY}.key", folder / f"{AUTHORITY}.pem"
    try:
        key = serialization.load_pem_private_key(key_path.read_bytes(), None)
        certificate = x509.load_pem_x509_certificate(certificate_path.read_bytes())
    except (OSError, ValueError) as error:
        raise SecurityError(f"{key_path} or {certificate_path} is unreadable: {error}") from None
    return key, certificate


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


def _option_for(subject: str) -> str:
    """What ``secure init`` needs to be told to make ``subject``'s certificate."""
    if subject.startswith("robot-"):
        return f" --robots {subject.removeprefix('robot-')}"
    if subject.startswith("observer-"):
        return f" --observers {subject.removeprefix('observer-')}"
    return ""


def check_subject(folder: Path, subject: str) -> None:
    """Check that ``folder`` holds a usable certificate of its authority for ``subject``.

    Raises:
        SecurityError: a file is missing or unreadable, the certificate is not valid now,
            names another subject, or was not signed by the folder's authority.
    """
    _require_cryptography()
    from cryptography import x509
    from cryptography.exceptions import InvalidSignature
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    paths = [folder / f"{AUTHORITY}.pem", folder / f"{subject}.pem", folder / f"{subject}.key"]
    made = f"fishswarm secure init{{}}{_option_for(subject)}"
    if paths[0].is_file() and not (folder / f"{AUTHORITY}.key").is_file():
        # A copy on a robot or laptop holds no authority's key: certificates are made where
        # it is, and copied here.
        files = ", ".join(path.name for path in paths)
        fix = (
            f"make them on the machine with the authority's folder (its {AUTHORITY}.key) with: "
            + made.format(" DIR")
            + f", then copy {files} here"
        )
    else:
        fix = "make them with: " + made.format(f" {folder}")
    observers = sorted(p.name.removesuffix(".pem") for p in folder.glob("observer-*.pem"))
    for path in paths:
        if not path.is_file():
            if subject == "observer" and observers and path != paths[0]:
                options = " or ".join(f"--name {n.removeprefix('observer-')}" for n in observers)
                fix = f"this folder holds the certificate of {', '.join(observers)}: give {options}"
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


def _swarm_of(authority: Any) -> str | None:
    """The swarm an authority's certificate was made for (its name: ``fishswarm <swarm>``)."""
    from cryptography.x509.oid import NameOID

    named = authority.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(named[0].value).removeprefix("fishswarm ") if named else None


def check_swarm(folder: Path, swarm: str) -> None:
    """Check that ``folder``'s authority is of ``swarm`` (its access control names that
    swarm's keys only: on another a client would be let through to nothing, and wait).

    Raises:
        SecurityError: it is of another swarm, with how to fix it.
    """
    _require_cryptography()
    from cryptography import x509

    path = folder / f"{AUTHORITY}.pem"
    if not path.is_file():
        return  # check_subject says so, with how to make it
    try:
        authority = x509.load_pem_x509_certificate(path.read_bytes())
    except ValueError:
        return  # check_subject says so
    theirs = _swarm_of(authority)
    if theirs is not None and theirs != swarm:
        raise SecurityError(
            f"{folder} secures swarm {theirs!r}, not {swarm!r}: give --swarm {theirs}, or the "
            f"folder of swarm {swarm!r} ('fishswarm secure init DIR --swarm {swarm}' makes one)"
        )


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


def secure_run(
    folder: Path, keys: KeySpace, schools: Mapping[str, Sequence[int]], out: Path
) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """The session settings of a secured ``fishswarm run``: its router's (the folder's
    access control, extended with a rule set for each of the run's schools) and each
    school's worker's (a certificate signed for this run into ``out``). Without schools
    (the fish in the router's own process) the router's alone: nothing is signed, so the
    authority's key need not be there.

    Raises:
        SecurityError: see :func:`session_security` and :func:`issue_for_run`.
    """
    check_swarm(folder, keys.swarm)
    router = session_security(folder, "router", router=True)
    if not schools:
        return router, {}
    issue_for_run(folder, [school_subject(school) for school in schools], out)
    extra = access_control([], keys, schools)
    access = router["access_control"]
    known = {rule["id"] for rule in access["rules"]}
    access["rules"] += [rule for rule in extra["rules"] if rule["id"] not in known]
    access["subjects"] += extra["subjects"]
    access["policies"] += extra["policies"]
    workers = {school: session_security(out, school_subject(school)) for school in schools}
    return router, workers
