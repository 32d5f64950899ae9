"""What every ``fishswarm`` command shares: errors a user can fix, checked endpoints, client
sessions (secured or not), and running a command's actors under trio.

It imports only what a robot has (DESIGN §7): ``fishswarm robot`` runs on a BlueBot's Pi,
where scipy and mcap are not installed, and gets its helpers from here rather than from the
base station's commands in :mod:`fishswarm.cli.swarm`.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import trio

from fishswarm.actors.driver import HardwareError
from fishswarm.actors.security import SecurityError, check_swarm, session_security
from fishswarm.actors.session import ConnectError, SessionSettings, check_endpoint
from fishswarm.sim.scenario import ConfigError

if TYPE_CHECKING:
    from fishswarm.study.recording import Recording


class UserError(RuntimeError):
    """Something the user can fix: the message says what."""


USER_ERRORS: tuple[type[BaseException], ...] = (
    ConnectError,
    SecurityError,
    ConfigError,
    HardwareError,
)
"""Errors every command reports as a message, not a traceback (a command adds its own)."""


def endpoint_of(value: str, flag: str) -> str:
    """``value`` of ``flag`` if it is an endpoint Zenoh accepts.

    Raises:
        ConfigError: it is not, with why.
    """
    try:
        return check_endpoint(value)
    except ValueError as error:
        raise ConfigError(f"{flag}: {error}") from None


def refuse_unused(
    args: argparse.Namespace, flags: Mapping[str, str], *, applies: str, fix: str
) -> None:
    """Refuse the options of ``flags`` (an argument's name → its flag) that were given
    (not None) where this invocation would ignore them.

    Args:
        applies: when they apply, e.g. ``with --view``.
        fix: what to do, with ``{it}`` for "it" or "them".

    Raises:
        ConfigError: naming the options given, when they apply and what to do.
    """
    given = [flag for name, flag in flags.items() if getattr(args, name, None) is not None]
    if given:
        many = len(given) > 1
        raise ConfigError(
            f"{', '.join(given)} appl{'y' if many else 'ies'} only {applies}: "
            + fix.format(it="them" if many else "it")
        )


def client_settings(args: argparse.Namespace, subject: str, *, swarm: str) -> SessionSettings:
    """A client session to ``--connect``; with ``--secure DIR``, over mutual TLS with the
    certificate of ``subject`` (its folder checked to secure ``swarm``)."""
    return SessionSettings(
        mode="client",
        connect=[endpoint_of(args.connect, "--connect")],
        connect_timeout=args.connect_timeout,
        extra=secure_extra(args, subject, endpoint=args.connect, swarm=swarm),
    )


def secure_extra(
    args: argparse.Namespace,
    subject: str,
    *,
    endpoint: str,
    router: bool = False,
    swarm: str | None = None,
) -> dict[str, Any]:
    """The session settings of ``--secure DIR`` for ``subject`` (none without it), the
    folder checked to secure ``swarm`` (None: a router's, which serves any).

    Raises:
        ConfigError: ``--secure`` with an endpoint that is not ``tls/``, or a ``tls/`` one
            without ``--secure``.
        SecurityError: the subject's certificate cannot be used (which file, and why).
    """
    folder = getattr(args, "secure", None)
    check_secured_endpoint(
        endpoint,
        flag="--listen" if router else "--connect",
        secured=folder is not None,
        # TLS may come from a Zenoh configuration file instead (robot --zenoh-config).
        tls_elsewhere=getattr(args, "zenoh_config", None) is not None,
    )
    if folder is None:
        return {}
    if swarm is not None:
        check_swarm(folder, swarm)
    return session_security(folder, subject, router=router)


def check_secured_endpoint(
    endpoint: str, *, flag: str, secured: bool, tls_elsewhere: bool = False
) -> None:
    """Check that ``endpoint`` (given as ``flag``) is a tls/ one exactly when the swarm is
    secured (``--secure``), or TLS comes from elsewhere.

    Raises:
        ConfigError: which is missing, and how to fix it.
    """
    tls = endpoint.startswith("tls/")
    if not secured and tls and not tls_elsewhere:
        raise ConfigError(
            f"{flag} {endpoint} is a secured (tls/) endpoint: give --secure DIR, the "
            "folder 'fishswarm secure init' wrote"
        )
    if secured and not tls:
        raise ConfigError(
            f"{flag} {endpoint}: a secured swarm talks TLS only: give a tls/ endpoint, e.g. "
            f"tls/{endpoint.partition('/')[2] or '127.0.0.1:7447'}"
        )


def run_trio(
    main: Callable[[], Any], *, errors: tuple[type[BaseException], ...] = USER_ERRORS
) -> Any:
    """Run ``main`` under trio, SIGTERM stopping it as Ctrl-C does (a KeyboardInterrupt
    after its sessions and files are closed: what systemd and ``docker stop`` send).

    Raises:
        ConfigError: a bad argument found on the way (the command's usage error).
        UserError: another of ``errors`` (a user can fix them), with the first one's message.
        KeyboardInterrupt: Ctrl-C or SIGTERM.
    """
    try:
        return trio.run(_stopped_by_sigterm, main)
    except KeyboardInterrupt:
        raise
    except BaseExceptionGroup as group:
        interrupted, _ = group.split(KeyboardInterrupt)
        if interrupted is not None:
            raise KeyboardInterrupt from None
        usage, rest = group.split(ConfigError)
        if usage is not None and rest is None:
            raise ConfigError(_first_message(usage)) from None
        matched, rest = group.split(errors)
        if matched is not None and rest is None:
            raise UserError(_first_message(matched)) from None
        raise
    except ConfigError:
        raise
    except errors as error:
        raise UserError(str(error)) from None


async def _stopped_by_sigterm(main: Callable[[], Any]) -> Any:
    """``main``, cancelled by SIGTERM, which then comes out as a KeyboardInterrupt (a
    receiver opened later inside ``main``, e.g. a launcher's, takes SIGTERM while open)."""
    result: list[Any] = []
    async with trio.open_nursery() as nursery:

        async def watch() -> None:
            with trio.open_signal_receiver(signal.SIGTERM) as signals:
                async for _ in signals:
                    raise KeyboardInterrupt

        async def serve() -> None:
            result.append(await main())
            nursery.cancel_scope.cancel()

        nursery.start_soon(watch)
        nursery.start_soon(serve)
    return result[0] if result else None


def _first_message(error: BaseException) -> str:
    while isinstance(error, BaseExceptionGroup):
        error = error.exceptions[0]
    return str(error)


def prepare_file(path: Path | None, flag: str, *, example: str, suffix: str | None = None) -> None:
    """Check, before any work goes into it, that a command can write the file ``path`` of
    ``flag`` (None: not asked for); its folder is made.

    Args:
        path: the file.
        flag: the option that names it, for messages.
        example: a good value, for messages (e.g. ``runs/latest.mcap``).
        suffix: the suffix the file must have (e.g. ``.npz``: NumPy adds it to any other
            name), or None.

    Raises:
        ConfigError: it names a folder, lacks ``suffix``, or its folder cannot be made or
            written to; with which and how to fix it.
    """
    if path is None:
        return
    if str(path) in ("", ".") or path.is_dir():
        raise ConfigError(
            f"{flag} must name a file, e.g. {flag} {example}; {str(path)!r} is a folder"
        )
    if suffix is not None and path.suffix != suffix:
        raise ConfigError(
            f"{flag} must name a {suffix} file, e.g. {flag} {example}; got {path.name}"
        )
    prepare_folder(path.parent, flag, file=path)


def check_distinct_files(
    written: Mapping[str, Path | None], *, read: Mapping[str, Path] | None = None
) -> None:
    """Refuse options that would write one file twice, or write over a file the command
    reads, before any work is done (the later write would destroy the earlier).

    Args:
        written: each output option (e.g. ``--csv``) and its file (None: not asked for).
        read: what the command reads (e.g. ``the recording``) and its file.

    Raises:
        ConfigError: which two name one file, and what to do.
    """
    seen: dict[Path, str] = {path.resolve(): what for what, path in (read or {}).items()}
    for flag, path in written.items():
        if path is None:
            continue
        where = path.resolve()
        if where in seen:
            other = seen[where]
            reads = other in (read or {})
            raise ConfigError(
                f"{flag} {path} names the same file as "
                + (f"{other}, which this command reads" if reads else other)
                + f": give {flag} another file"
            )
        seen[where] = flag


def prepare_folder(folder: Path, flag: str, *, file: Path | None = None) -> None:
    """Make the output folder now (of ``file``, when the flag names a file in it), before
    hours of work go into it.

    Raises:
        ConfigError: it is a file, or cannot be made or written to, with which.
    """
    named = flag if file is None else f"{flag} {file}: its folder"
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{named} {folder} is a file: give a folder to write into")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        # A probe of its own name: two commands preparing one folder at once (two worlds
        # recording into runs/) must not remove each other's.
        handle, probe = tempfile.mkstemp(prefix=".fishswarm-write-test-", dir=folder)
        os.close(handle)
        os.unlink(probe)
    except OSError as error:
        raise ConfigError(f"{named} {folder}: cannot write there ({error.strerror})") from None


def read_recording_for(path: Path, *, at_least: int, purpose: str) -> Recording:
    """The recording at ``path`` with at least ``at_least`` snapshots (a note on standard
    error when it was cut short).

    Raises:
        UserError: it cannot be read, or holds too few snapshots to ``purpose``.
    """
    from fishswarm.study.recording import RecordingError, read_recording

    try:
        recording = read_recording(path)
    except RecordingError as error:
        raise UserError(str(error)) from None
    if note := recording.note(path):
        print(note, file=sys.stderr)
    if len(recording.snapshots) < at_least:
        few = "no snapshots" if at_least == 1 else f"fewer than {at_least} snapshots"
        raise UserError(f"{path} holds {few}: nothing to {purpose}")
    return recording
