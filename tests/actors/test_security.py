"""A secured swarm over real Zenoh on 127.0.0.1: mutual TLS, and access control by the
certificate's common name."""

from __future__ import annotations

import contextlib
import datetime
import json
import shutil
from pathlib import Path
from typing import Any

import pytest
import trio

from fishswarm.actors.security import (
    ACCESS_FILE,
    SecurityError,
    access_control,
    check_subject,
    init_secure,
    session_security,
)
from fishswarm.actors.session import ConnectError, SessionSettings, open_session
from fishswarm.actors.zenoh_bus import ZenohBus
from fishswarm.protocols.keys import KeySpace
from tests.conftest import free_port, run_trio, subscription

pytestmark = pytest.mark.integration

KEYS = KeySpace("default")


@pytest.fixture(scope="module")
def secure_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("secure")
    init_secure(folder, robots=[1, 2], observers=["lab"])
    return folder


def _settings(
    folder: Path, subject: str, endpoint: str, *, router: bool = False
) -> SessionSettings:
    extra = session_security(folder, subject, router=router)
    if router:
        return SessionSettings(mode="router", listen=[endpoint], extra=extra)
    return SessionSettings(mode="client", connect=[endpoint], connect_timeout=3.0, extra=extra)


def test_secure_init_writes_an_authority_a_certificate_per_subject_and_the_access_control(
    secure_dir: Path,
) -> None:
    names = sorted(path.name for path in secure_dir.iterdir())
    for subject in ("ca", "router", "world", "channel", "admin", "observer", "observer-lab",
                    "robot-1", "robot-2"):  # fmt: skip
        assert f"{subject}.pem" in names and f"{subject}.key" in names
        if subject != "ca":
            check_subject(secure_dir, subject)
    assert (secure_dir / "robot-1.key").stat().st_mode & 0o077 == 0  # keys for the owner only
    access = json.loads((secure_dir / ACCESS_FILE).read_text())
    assert access["default_permission"] == "deny"
    # Robot 1 may put its own command and nobody else's.
    rules = {rule["id"]: rule for rule in access["rules"]}
    assert rules["robot-1-publish"]["key_exprs"][0] == "fishswarm/default/fish/1/command"
    assert not any("fish/2" in key for key in rules["robot-1-publish"]["key_exprs"])
    # An observer publishes nothing; what it subscribes to it may also receive: a put on
    # egress only (from the router to it), never on ingress (from it to the router).
    assert "observer-publish" not in rules
    assert rules["observer-subscribe"]["messages"] == ["declare_subscriber"]
    assert rules["observer-receive"]["messages"] == ["put", "delete"]
    assert rules["observer-receive"]["flows"] == ["egress"]
    assert rules["observer-receive"]["key_exprs"] == rules["observer-subscribe"]["key_exprs"]


def test_certificates_that_cannot_be_used_get_a_clear_message(
    secure_dir: Path, tmp_path: Path
) -> None:
    with pytest.raises(
        SecurityError,
        match=r"robot-7.pem is missing: no certificate for 'robot-7' \(make them with: "
        r"fishswarm secure init .* --robots 7\)",
    ):
        check_subject(secure_dir, "robot-7")
    # Robot 1's certificate copied under robot 2's name is still robot 1's.
    copy = tmp_path / "copy"
    shutil.copytree(secure_dir, copy)
    shutil.copy(copy / "robot-1.pem", copy / "robot-2.pem")
    with pytest.raises(SecurityError, match=r"is the certificate of 'robot-1', not of 'robot-2'"):
        check_subject(copy, "robot-2")
    # A certificate of another authority.
    other = tmp_path / "other"
    init_secure(other)
    shutil.copy(other / "world.pem", copy / "world.pem")
    with pytest.raises(SecurityError, match=r"was not signed by the authority"):
        check_subject(copy, "world")
    # A robot's or a laptop's copy holds no authority key: its certificates are made where
    # the key is and copied (following 'secure init' here led to "half an authority").
    laptop = tmp_path / "laptop"
    laptop.mkdir()
    for name in ("ca.pem", "observer-lab.pem", "observer-lab.key"):
        shutil.copy(secure_dir / name, laptop / name)
    with pytest.raises(SecurityError) as missing:
        check_subject(laptop, "robot-1")
    assert str(missing.value).endswith(
        "(make them on the machine with the authority's folder (its ca.key) with: fishswarm "
        "secure init DIR --robots 1, then copy ca.pem, robot-1.pem, robot-1.key here)"
    )
    # The observer's certificate is there under its name: give --name.
    with pytest.raises(SecurityError) as unnamed:
        check_subject(laptop, "observer")
    assert str(unnamed.value).endswith(
        "(this folder holds the certificate of observer-lab: give --name lab)"
    )
    check_subject(laptop, "observer-lab")
    # Without the authority's certificate either, that is what is missing first: the
    # folder of 'secure init' is the fix, not another --name.
    (laptop / "ca.pem").unlink()
    with pytest.raises(SecurityError) as bare:
        check_subject(laptop, "observer")
    assert f"{laptop / 'ca.pem'} is missing" in str(bare.value)
    assert str(bare.value).endswith(f"(make them with: fishswarm secure init {laptop})")
    # An expired one, signed by the right authority.
    _expired(copy, "channel")
    with pytest.raises(SecurityError, match=r"not now: renew it"):
        check_subject(copy, "channel")
    (copy / ACCESS_FILE).unlink()
    with pytest.raises(SecurityError, match=r"access_control.json is missing"):
        session_security(copy, "router", router=True)


def test_secure_init_on_a_folder_with_an_authority_adds_to_it(
    secure_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "lab"
    shutil.copytree(secure_dir, folder)
    given_out = {name: (folder / name).read_bytes() for name in ("ca.pem", "robot-2.pem")}
    # A key pair that is no subject's (the lab's own) is neither counted nor removed.
    (folder / "notes.pem").write_text("kept")
    (folder / "notes.key").write_text("kept")
    written = init_secure(folder, robots=[1, 3], observers=["bob"])
    # Only the subjects without a certificate get one, signed by the same authority, and
    # everything given out before stays as it was and valid.
    assert sorted(path.name for path in written) == [
        "access_control.json", "observer-bob.key", "observer-bob.pem", "robot-3.key",
        "robot-3.pem",
    ]  # fmt: skip
    for name, content in given_out.items():
        assert (folder / name).read_bytes() == content
    for subject in ("robot-1", "robot-2", "robot-3", "observer-lab", "observer-bob", "world"):
        check_subject(folder, subject)
    # The router's access control names every subject with a certificate there.
    rules = {rule["id"] for rule in json.loads((folder / ACCESS_FILE).read_text())["rules"]}
    assert {"robot-2-publish", "robot-3-publish", "observer-lab-subscribe"} <= rules
    # Another swarm's keys are not written over this authority's.
    with pytest.raises(SecurityError, match=r"authority is of swarm 'default', not 'lab'"):
        init_secure(folder, robots=[5], swarm="lab")
    # A new authority only when asked for: the old certificates are then not accepted, and
    # those of subjects not named again are removed (files that are no subject's stay).
    init_secure(folder, robots=[1], replace=True)
    assert (folder / "ca.pem").read_bytes() != given_out["ca.pem"]
    with pytest.raises(SecurityError, match=r"robot-2.pem is missing.*--robots 2"):
        check_subject(folder, "robot-2")
    assert sorted(p.stem for p in folder.glob("*.pem")) == [
        "admin", "ca", "channel", "notes", "observer", "robot-1", "router", "world",
    ]  # fmt: skip
    for subject in ("robot-1", "observer", "world"):
        check_subject(folder, subject)
    # Half an authority is not guessed at.
    (folder / "ca.key").unlink()
    with pytest.raises(SecurityError, match=r"holds half an authority.*--force"):
        init_secure(folder, robots=[4])
    from fishswarm.cli import main

    assert main(["secure", "init", str(folder), "--robots", "4"]) == 1  # a message, no traceback
    assert main(["secure", "init", str(folder), "--force"]) == 0
    assert "Removed the old authority's certificates of robot-1." in capsys.readouterr().err
    assert not (folder / "robot-1.pem").exists()


def test_a_tls_endpoint_needs_secure_unless_a_zenoh_configuration_brings_tls() -> None:
    import argparse

    from fishswarm.cli.common import secure_extra
    from fishswarm.sim.scenario import ConfigError

    bare = argparse.Namespace(secure=None)
    with pytest.raises(ConfigError, match=r"is a secured \(tls/\) endpoint: give --secure DIR"):
        secure_extra(bare, "robot-1", endpoint="tls/10.0.0.1:7447")
    configured = argparse.Namespace(secure=None, zenoh_config="/etc/fishswarm/zenoh.json5")
    assert secure_extra(configured, "robot-1", endpoint="tls/10.0.0.1:7447") == {}


def _expired(folder: Path, subject: str) -> None:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.x509.oid import NameOID

    authority_key = serialization.load_pem_private_key((folder / "ca.key").read_bytes(), None)
    authority = x509.load_pem_x509_certificate((folder / "ca.pem").read_bytes())
    key = serialization.load_pem_private_key((folder / f"{subject}.key").read_bytes(), None)
    past = datetime.datetime(2020, 1, 1, tzinfo=datetime.UTC)
    certificate = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, subject)]))
        .issuer_name(authority.subject)
        .public_key(key.public_key())  # type: ignore[arg-type]
        .serial_number(x509.random_serial_number())
        .not_valid_before(past)
        .not_valid_after(past + datetime.timedelta(days=1))
        .sign(authority_key, hashes.SHA256())  # type: ignore[arg-type]
    )
    (folder / f"{subject}.pem").write_bytes(certificate.public_bytes(serialization.Encoding.PEM))


def test_only_certified_clients_connect_and_each_may_put_only_its_own_keys(
    secure_dir: Path,
) -> None:
    endpoint = f"tls/127.0.0.1:{free_port()}"

    async def main() -> dict[str, list[str]]:
        async with open_session(_settings(secure_dir, "router", endpoint, router=True)):
            # No certificate: the router's mutual TLS refuses the client.
            bare = SessionSettings(
                mode="client", connect=[endpoint], connect_timeout=2.0,
                extra={"transport/link/tls": {"root_ca_certificate": str(secure_dir / "ca.pem")}},
            )  # fmt: skip
            with pytest.raises(ConnectError):
                async with open_session(bare):
                    pass
            async with (
                open_session(_settings(secure_dir, "world", endpoint)) as world_session,
                open_session(_settings(secure_dir, "observer-lab", endpoint)) as observer_session,
                open_session(_settings(secure_dir, "robot-1", endpoint)) as robot1_session,
                open_session(_settings(secure_dir, "robot-2", endpoint)) as robot2_session,
            ):
                world, observer = ZenohBus(world_session), ZenohBus(observer_session)
                robot1, robot2 = ZenohBus(robot1_session), ZenohBus(robot2_session)
                heard: dict[str, list[str]] = {"world": [], "observer": [], "robot-2": []}
                async with (
                    subscription(world, KEYS.command("*")) as commands,
                    subscription(observer, KEYS.snapshot) as snapshots,
                    subscription(robot2, KEYS.perception(2)) as perceptions,
                ):
                    # Wait until the routes are up: the world's snapshots reach the observer.
                    with trio.fail_after(10):
                        while True:
                            world.put(KEYS.snapshot, b"snapshot")
                            with trio.move_on_after(0.1):
                                await snapshots.receive()
                                break
                    snapshots.drain()
                    # Not allowed: robot 1 commanding fish 2, the observer commanding fish 1,
                    # feeding robot 2 a perception, or putting on the world's control key.
                    robot1.put(KEYS.command(2), b"robot-1 as fish 2")
                    observer.put(KEYS.command(1), b"observer as fish 1")
                    observer.put(KEYS.perception(2), b"observer as the world")
                    observer.put(KEYS.control, b"observer stops the run")
                    # Allowed: robot 1 commanding its own fish, the world a perception.
                    robot1.put(KEYS.command(1), b"robot-1 as fish 1")
                    world.put(KEYS.perception(2), b"world to fish 2")
                    world.put(KEYS.snapshot, b"snapshot")
                    with trio.fail_after(10):
                        heard["world"].append((await commands.receive())[1].decode())
                        heard["robot-2"].append((await perceptions.receive())[1].decode())
                        heard["observer"].append((await snapshots.receive())[1].decode())
                    # Whatever else was coming has come by now.
                    await trio.sleep(0.5)
                    heard["world"] += [payload.decode() for _, payload in commands.drain()]
                    heard["robot-2"] += [payload.decode() for _, payload in perceptions.drain()]
                    return heard

    heard = run_trio(main)
    assert heard == {
        "world": ["robot-1 as fish 1"],
        "observer": ["snapshot"],
        "robot-2": ["world to fish 2"],
    }


def test_a_subject_may_not_put_on_the_keys_it_only_subscribes_to(secure_dir: Path) -> None:
    endpoint = f"tls/127.0.0.1:{free_port()}"
    # Each forger subscribes to the key it forges (a robot to the pulse and the robots'
    # order, an observer to the snapshots); only the world and the admin may put there.
    forged = [
        ("robot-1", KEYS.world_pulse),
        ("robot-1", KEYS.robot_order),
        ("observer-lab", KEYS.snapshot),
        ("robot-1", KEYS.snapshot),
    ]
    genuine = [("world", KEYS.world_pulse), ("admin", KEYS.robot_order), ("world", KEYS.snapshot)]

    async def main() -> list[tuple[str, str]]:
        subjects = ["world", "admin", "observer-lab", "robot-1", "robot-2"]
        async with contextlib.AsyncExitStack() as stack:
            await stack.enter_async_context(
                open_session(_settings(secure_dir, "router", endpoint, router=True))
            )
            buses = {
                subject: ZenohBus(
                    await stack.enter_async_context(
                        open_session(_settings(secure_dir, subject, endpoint))
                    )
                )
                for subject in subjects
            }
            inboxes = {
                key: await stack.enter_async_context(subscription(buses["robot-2"], key))
                for key in (KEYS.world_pulse, KEYS.robot_order, KEYS.snapshot)
            }
            # Wait until the routes are up: each genuine put reaches robot 2.
            for subject, key in genuine:
                with trio.fail_after(10):
                    while True:
                        buses[subject].put(key, b"probe")
                        with trio.move_on_after(0.1):
                            await inboxes[key].receive()
                            break
            await trio.sleep(0.3)
            for inbox in inboxes.values():
                inbox.drain()
            for subject, key in forged + genuine:
                buses[subject].put(key, subject.encode())
            await trio.sleep(1.0)  # whatever was let through has come by now
            return sorted(
                (key, payload.decode())
                for key, inbox in inboxes.items()
                for _, payload in inbox.drain()
            )

    heard = run_trio(main)
    assert heard == sorted((key, subject) for subject, key in genuine)


def test_the_channel_may_ask_the_world_for_its_run_and_a_robot_may_not(
    secure_dir: Path,
) -> None:
    """A standalone channel takes each run's range, loss and seed from the world's answer on
    ``world/scenario``: its certificate may query there (a robot's may not)."""
    from fishswarm.actors.control import ask_scenario, run_control
    from fishswarm.actors.world import World, WorldSettings
    from fishswarm.sim.scenario import Scenario

    endpoint = f"tls/127.0.0.1:{free_port()}"
    scenario = Scenario(fish=2, channel_loss=0.5, seed=3)

    async def main() -> tuple[Scenario | None, Scenario | None]:
        async with (
            open_session(_settings(secure_dir, "router", endpoint, router=True)),
            open_session(_settings(secure_dir, "world", endpoint)) as world_session,
            open_session(_settings(secure_dir, "observer-lab", endpoint)) as observer_session,
            open_session(_settings(secure_dir, "channel", endpoint)) as channel_session,
            open_session(_settings(secure_dir, "robot-1", endpoint)) as robot_session,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(run_control, world_session, World(WorldSettings(scenario)))
            # Wait until the routes are up: the observer, allowed too, hears the answer.
            with trio.fail_after(10):
                while await ask_scenario(observer_session, KEYS, timeout=0.5) is None:
                    pass
            channel_told = await ask_scenario(channel_session, KEYS, timeout=2.0)
            robot_told = await ask_scenario(robot_session, KEYS, timeout=2.0)
            nursery.cancel_scope.cancel()
        return channel_told, robot_told

    channel_told, robot_told = run_trio(main)
    assert channel_told is not None
    assert (channel_told.channel_loss, channel_told.seed) == (0.5, 3)
    assert robot_told is None


def test_the_access_control_names_every_subject_once() -> None:
    access = access_control(["router", "world", "observer", "robot-3"], KEYS)
    assert [subject["id"] for subject in access["subjects"]] == ["world", "observer", "robot-3"]
    assert all(policy["rules"][-1] == "liveliness" for policy in access["policies"])
    with pytest.raises(ValueError, match="unknown subject 'stranger'"):
        access_control(["stranger"], KEYS)


def test_a_secured_run_with_an_observer_that_tries_to_steer_it_equals_a_clean_run(
    secure_dir: Path, tmp_path: Path
) -> None:
    import numpy as np

    from fishswarm.actors.launcher import LaunchSettings, launch_swarm
    from fishswarm.protocols.codec import encode
    from fishswarm.protocols.messages import Command
    from fishswarm.sim.engine import simulate_batch
    from fishswarm.sim.scenario import Scenario
    from fishswarm.study.recording import read_recording

    # A formation with flags flowing over two worker processes: each worker has only a
    # certificate signed for this run, and receives only its own fish's deliveries.
    scenario = Scenario(
        fish=6, behavior="formation", formation="column", duration=6.0, seed=3,
        controller="pid", control_period=0.5, spawn_radius=0.4, spacing=0.25,
    )  # fmt: skip
    endpoint = f"tls/127.0.0.1:{free_port()}"
    record = tmp_path / "secured.mcap"
    settings = LaunchSettings(scenario, procs=2, listen=endpoint, record=record, secure=secure_dir)
    keys = scenario.keys
    forged = encode(Command(0, 0, np.array([1.0, 0.0, 1.0, 0.0]), True))

    async def main() -> tuple[Any, int]:
        result: list[Any] = []
        attempts = 0

        async def launch() -> None:
            result.append(await launch_swarm(settings))

        async with trio.open_nursery() as nursery:
            nursery.start_soon(launch)
            # An observer (a certificate of this swarm) tries to command fish 0, to feed
            # fish 1 a perception and to stop the run, over and over while it runs.
            await trio.sleep(0.5)
            async with open_session(_settings(secure_dir, "observer-lab", endpoint)) as session:
                bus = ZenohBus(session)
                while not result:
                    for _ in range(20):
                        bus.put(keys.command(0), forged)
                        bus.put(keys.school_commands("worker-0"), forged)
                        bus.put(keys.school_perceptions("worker-1"), b"\x93\x01\x02\x03")
                        bus.put(keys.outbox(2), b"\x93\x01\x02\x03")
                        attempts += 1
                    await trio.sleep(0.05)
        return result[0], attempts

    result, attempts = run_trio(main, timeout=120)
    assert result.exit_code == 0 and attempts > 0
    # Had anything forged reached the world, the channel or a worker, it would be rejected
    # there and counted.
    assert set(result.summary["counts"]["rejected"].values()) == {0}
    assert result.summary["counts"]["deliveries"] > 0
    observed = read_recording(record).arrays()
    np.testing.assert_array_equal(observed["pos"], simulate_batch(scenario).position)


@pytest.mark.slow
@pytest.mark.parametrize("vouched_only", [True, False])
def test_a_fake_fish_shown_by_a_liveliness_token_is_not_admitted_to_a_secured_run(
    secure_dir: Path, tmp_path: Path, vouched_only: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    import numpy as np

    from fishswarm.actors.launcher import LaunchSettings, launch_swarm
    from fishswarm.sim.engine import simulate_batch
    from fishswarm.sim.scenario import Scenario
    from fishswarm.study.recording import read_recording

    # Zenoh's access control does not filter liveliness: any certified client (here an
    # observer) can show a token saying "fish 9 is alive", on its own keys or as a fish of a
    # run's school. A secured world admits only fish vouched for on their own about keys.
    # Without that defence (vouched_only False, forced here) the fake fish gets in.
    if not vouched_only:
        from fishswarm.actors.world import WorldSettings

        monkeypatch.setattr(
            "fishswarm.actors.launcher.WorldSettings",
            lambda *a, **k: WorldSettings(*a, **{**k, "vouched_only": False}),
        )
    # In real time, so that the tokens come and go while the world waits and runs.
    scenario = Scenario(fish=4, duration=3.0, seed=5, control_period=0.5, time_mode="realtime")
    endpoint = f"tls/127.0.0.1:{free_port()}"
    record = tmp_path / "run.mcap"
    settings = LaunchSettings(scenario, listen=endpoint, record=record, secure=secure_dir,
                              command_timeout=1.0)  # fmt: skip
    keys = scenario.keys

    async def main() -> Any:
        result: list[Any] = []

        async def launch() -> None:
            result.append(await launch_swarm(settings))

        async with trio.open_nursery() as nursery:
            nursery.start_soon(launch)
            await trio.sleep(0.3)
            async with open_session(_settings(secure_dir, "observer-lab", endpoint)) as session:
                bus = ZenohBus(session)
                own = bus.declare_token(keys.alive("fish", 9))
                schooled = bus.declare_token(keys.alive("fish", 8, "worker-0"))
                # A real fish (1, served by the run's school) shown on its own keys, then
                # gone: it would re-route the fish's commands, then lose it.
                impostor = bus.declare_token(keys.alive("fish", 1))
                await trio.sleep(1.0)
                impostor.undeclare()
                while not result:
                    await trio.sleep(0.05)
                own.undeclare()
                schooled.undeclare()
        return result[0]

    result = run_trio(main, timeout=120)
    ids = {int(i) for s in read_recording(record).snapshots for i in s.ids}
    if vouched_only:
        assert result.exit_code == 0 and ids == {0, 1, 2, 3}
        assert result.summary["counts"]["joined_fish"] == 0
        assert result.summary["counts"]["lost_fish"] == 0
        positions = read_recording(record).arrays()["pos"]
        np.testing.assert_array_equal(positions, simulate_batch(scenario).position)
    else:
        assert ids & {8, 9}  # the threat is real: the world took a fish nobody runs


def test_secure_init_with_a_new_host_renews_the_routers_certificate_and_nothing_else(
    secure_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The router is to be reached at 10.0.0.1 too: secure init on the existing folder
    renews the router's certificate under the same authority, naming the new host beside
    the old names; every other file given out stays as it was, and asked again, nothing
    changes. (It used to say it added nothing, and clients connecting by the new address
    were refused.)"""
    from cryptography import x509

    from fishswarm.actors.security import AUTHORITY
    from fishswarm.cli import main

    folder = tmp_path / "lab"
    shutil.copytree(secure_dir, folder)
    before = {path.name: path.read_bytes() for path in folder.iterdir()}

    def router_names() -> list[str]:
        certificate = x509.load_pem_x509_certificate((folder / "router.pem").read_bytes())
        names = certificate.extensions.get_extension_for_class(x509.SubjectAlternativeName)
        return [str(getattr(name.value, "exploded", name.value)) for name in names.value]

    assert router_names() == ["localhost", "127.0.0.1"]
    assert main(["secure", "init", str(folder), "--host", "10.0.0.1"]) == 0
    said = capsys.readouterr().err
    assert "renewed the router's certificate to name 10.0.0.1 too" in said
    assert "Restart the router" in said
    assert router_names() == ["localhost", "127.0.0.1", "10.0.0.1"]
    changed = sorted(
        name for name, content in before.items() if (folder / name).read_bytes() != content
    )
    assert changed == ["router.key", "router.pem"]
    check_subject(folder, "router")
    assert (folder / f"{AUTHORITY}.pem").read_bytes() == before[f"{AUTHORITY}.pem"]
    renewed = (folder / "router.pem").read_bytes()
    assert main(["secure", "init", str(folder), "--host", "10.0.0.1", "--days", "5"]) == 0
    said = capsys.readouterr().err
    assert "renewed" not in said
    # Nothing new to make: the other --days changes no certificate, and the message says so.
    assert "added no new certificate (--days counts for certificates made now only)" in said
    assert main(["secure", "init", str(folder), "--host", "10.0.0.1"]) == 0
    said = capsys.readouterr().err  # no --days given: nothing to say of it
    assert "added no new certificate (signed by it" in said and "--days" not in said
    assert (folder / "router.pem").read_bytes() == renewed
    # A second host besides the first: the message names the new one only.
    assert main(["secure", "init", str(folder), "--host", "10.0.0.1", "--host", "lab.local"]) == 0
    assert "to name lab.local too" in capsys.readouterr().err
    assert router_names() == ["localhost", "127.0.0.1", "10.0.0.1", "lab.local"]


def test_secure_init_makes_each_subject_once_and_refuses_names_it_cannot_use(
    tmp_path: Path,
) -> None:
    folder = tmp_path / "keys"
    init_secure(folder, robots=[1, 1], observers=["lab", "lab"])
    rules = [rule["id"] for rule in json.loads((folder / ACCESS_FILE).read_text())["rules"]]
    assert len(rules) == len(set(rules))  # the router refuses a rule named twice
    assert rules.count("robot-1-publish") == 1
    for bad, reason in (
        ({"observers": [""]}, "observer name '' is not valid"),
        ({"observers": ["a/b"]}, "observer name 'a/b' is not valid"),
        ({"hosts": ["not a host!"]}, "neither an IP address nor a host name"),
        ({"hosts": [""]}, "neither an IP address nor a host name"),
        ({"days": 36_501}, "1 to 36500 days"),
        ({"robots": [10**18]}, "robot id must be in"),
    ):
        with pytest.raises(ValueError, match=reason):
            init_secure(tmp_path / "refused", **bad)
        assert not (tmp_path / "refused").exists()  # nothing half written


def test_secure_init_always_names_this_machine_for_the_router(tmp_path: Path) -> None:
    from cryptography import x509

    from fishswarm.cli import main

    assert main(["secure", "init", str(tmp_path / "k"), "--host", "10.0.0.1"]) == 0
    router = x509.load_pem_x509_certificate((tmp_path / "k" / "router.pem").read_bytes())
    names = router.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert {str(a) for a in names.get_values_for_type(x509.IPAddress)} == {
        "127.0.0.1", "10.0.0.1",
    }  # fmt: skip
    assert names.get_values_for_type(x509.DNSName) == ["localhost"]
    # Wildcard and fully qualified names are certificate names too.
    assert main(["secure", "init", str(tmp_path / "w"), "--host", "*.lab", "--host", "r.lab."]) == 0
    # Certificates left without their authority (its files lost) go with a new one.
    (tmp_path / "k" / "ca.pem").unlink()
    (tmp_path / "k" / "ca.key").unlink()
    assert main(["secure", "init", str(tmp_path / "k"), "--robots", "2"]) == 0
    for subject in ("robot-2", "observer", "world"):
        check_subject(tmp_path / "k", subject)
    for argv in (["--observers", "a/b"], ["--robots", str(10**18)], ["--swarm", "a b"]):
        with pytest.raises(SystemExit) as refused:
            main(["secure", "init", str(tmp_path / "r"), *argv])
        assert refused.value.code == 2


def test_a_secured_run_without_workers_needs_no_authority_key(
    secure_dir: Path, tmp_path: Path
) -> None:
    # On the router's machine the authority's key may have been put away: a run whose
    # fish live in the router's own process signs no certificate, one with workers does.
    from fishswarm.actors.security import AUTHORITY, secure_run

    folder = tmp_path / "keyless"
    shutil.copytree(secure_dir, folder)
    (folder / f"{AUTHORITY}.key").unlink()
    router, workers = secure_run(folder, KEYS, {}, tmp_path / "signed")
    assert workers == {} and router["access_control"]["rules"]
    with pytest.raises(SecurityError, match="authority's key"):
        secure_run(folder, KEYS, {"worker-0": [0, 1]}, tmp_path / "signed")


def test_a_folder_of_another_swarm_is_refused_at_once_with_the_swarm_it_secures(
    tmp_path: Path,
) -> None:
    # Its access control names the keys of swarm "default" only: a fish of swarm "lab2"
    # was let through to nothing and waited in silence.
    from fishswarm.actors.security import check_swarm
    from fishswarm.cli import main

    folder = tmp_path / "keys"
    init_secure(folder, robots=[0], observers=["laptop"])
    check_swarm(folder, "default")
    with pytest.raises(SecurityError, match=r"keys secures swarm 'default', not 'lab2': give "):
        check_swarm(folder, "lab2")
    endpoint = f"tls/127.0.0.1:{free_port()}"
    for args in (
        ["fish", "--id", "0", "--secure", str(folder), "--swarm", "lab2", "--connect", endpoint],
        ["observe", "--secure", str(folder), "--name", "laptop", "--swarm", "lab2",
         "--connect", endpoint],
    ):  # fmt: skip
        assert main(args) == 1
