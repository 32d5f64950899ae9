"""The Ansible deployment (deploy/): it lints clean, its playbook runs in check mode against
this machine, and the service it installs starts the robot with arguments our CLI accepts."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from fishswarm.cli.parsers import build_parser
from tests.behaviors.example_plugin import EXAMPLE
from tests.conftest import free_port

pytestmark = pytest.mark.integration

DEPLOY = Path(__file__).resolve().parents[1] / "deploy"
BIN = Path(sys.executable).parent
ROLE = DEPLOY / "roles" / "fishswarm"


def ansible(
    tool: str, *args: str, cwd: Path = DEPLOY, roles: Path | None = None
) -> subprocess.CompletedProcess[str]:
    executable = BIN / tool
    if not executable.exists():
        pytest.fail(f"{tool} is missing: pip install -e '.[dev]' installs it")
    environment = {**os.environ, "ANSIBLE_NOCOLOR": "1", "NO_COLOR": "1"}
    if roles is not None:
        environment["ANSIBLE_ROLES_PATH"] = str(roles)
    return subprocess.run(
        [str(executable), *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        env=environment,
        check=False,
    )


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("dist")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(folder),
            str(DEPLOY.parent),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    return next(folder.glob("fishswarm-*.whl"))


@pytest.fixture(scope="module")
def example_wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel of the example package that adds a behaviour (examples/behavior_plugin)."""
    folder = tmp_path_factory.mktemp("example")
    source = shutil.copytree(EXAMPLE, folder / "source")  # built there: the tree stays clean
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
         "-w", str(folder), str(source)],
        check=True, capture_output=True, timeout=300,
    )  # fmt: skip
    return next(folder.glob("fishswarm_nearest-*.whl"))


def inventory(folder: Path, wheel: Path, **robot: object) -> Path:
    values = {
        "ansible_connection": "local",
        "ansible_python_interpreter": sys.executable,
        "ansible_become": False,
        "fishswarm_hardware": "mock",
        "fishswarm_router": "tcp/10.0.0.1:7447",
        "fishswarm_wheel": str(wheel),
        **robot,
    }
    lines = ["robots:", "  hosts:", "    localhost:"]
    lines += [
        f"      {key}: {value!r}" if isinstance(value, str) else f"      {key}: {value}"
        for key, value in values.items()
    ]
    path = folder / "inventory.yml"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.slow
def test_the_deployment_lints_clean() -> None:
    result = ansible("ansible-lint", "--offline")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Passed" in result.stdout + result.stderr


@pytest.mark.slow
def test_the_playbook_runs_in_check_mode_against_this_machine(tmp_path: Path, wheel: Path) -> None:
    path = inventory(tmp_path, wheel, fish_id=3)
    result = ansible("ansible-playbook", "-i", str(path), "site.yml", "--check", "--diff")
    assert result.returncode == 0, result.stdout + result.stderr
    recap = re.search(r"localhost\s+: ok=(\d+)\s+changed=(\d+).*failed=(\d+)", result.stdout)
    assert recap is not None, result.stdout
    assert int(recap.group(3)) == 0 and int(recap.group(1)) >= 8
    # What it would write: the robot's settings and the service that runs fish 3's robot.
    assert "FISHSWARM_ROUTER=tcp/10.0.0.1:7447" in result.stdout
    assert "ExecStart=/opt/fishswarm/venv/bin/fishswarm robot --id %i" in result.stdout


def test_a_robot_without_a_fish_id_is_refused_with_how_to_fix_it(
    tmp_path: Path, wheel: Path
) -> None:
    result = ansible(
        "ansible-playbook", "-i", str(inventory(tmp_path, wheel)), "site.yml", "--check"
    )
    assert result.returncode != 0
    assert "give every robot a fish_id in the inventory" in result.stdout


def render(template: str, folder: Path, **variables: str) -> str:
    """A template of the role, rendered by Ansible with the role's defaults."""
    destination = folder / template.removesuffix(".j2")
    extra = " ".join(f"{key}={value}" for key, value in variables.items())
    result = ansible(
        "ansible",
        "localhost",
        "-i",
        "localhost,",
        "-c",
        "local",
        "-e",
        f"ansible_python_interpreter={sys.executable}",
        "-e",
        f"@{ROLE / 'defaults' / 'main.yml'}",
        "-e",
        extra,
        "-m",
        "ansible.builtin.template",
        "-a",
        f"src={ROLE / 'templates' / template} dest={destination}",
        cwd=folder,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return destination.read_text()


def _service_arguments(folder: Path, **variables: str) -> list[str]:
    """The arguments the robot's service gives fishswarm, as systemd makes them of the unit
    and the environment file: ``%i`` the instance, ``${NAME}`` one word, ``$NAME`` split
    into words (none when empty)."""
    settings = render("fishswarm.env.j2", folder, fish_id="7", **variables)
    environment = dict(
        line.split("=", 1) for line in settings.splitlines() if line and not line.startswith("#")
    )
    unit = render("fishswarm-fish@.service.j2", folder, fish_id="7")
    command = next(line for line in unit.splitlines() if line.startswith("ExecStart="))
    words = shlex.split(command.removeprefix("ExecStart="))
    assert words[0] == "/opt/fishswarm/venv/bin/fishswarm"
    made: list[str] = []
    for word in words[1:]:
        if re.fullmatch(r"\$\w+", word):
            made += environment[word[1:]].split()
        else:
            made.append(
                re.sub(r"\$\{(\w+)\}", lambda m: environment[m.group(1)], word.replace("%i", "7"))
            )
    return made


@pytest.mark.slow
def test_a_robot_given_the_worlds_scenario_file_and_fish_decides_with_them(
    tmp_path: Path,
) -> None:
    from fishswarm.cli.parsers import scenario_from

    plain = build_parser().parse_args(_service_arguments(tmp_path, fishswarm_hardware="mock"))
    assert (plain.behavior, plain.control_period) == ("dispersion", 1.0)
    assert plain.config is None and plain.fish is None
    words = _service_arguments(
        tmp_path, fishswarm_hardware="mock", fishswarm_config="/lab/formation.toml",
        fishswarm_fish="8",
    )  # fmt: skip
    given = build_parser().parse_args(words)
    assert given.config == Path("/etc/fishswarm/scenario.toml") and given.fish == 8
    assert given.behavior is None and given.control_period is None  # the file's
    # The file as the play copies it: the robot's fish take the world's formation, for 8.
    words[words.index("--config") + 1] = str(DEPLOY.parent / "experiments" / "formation.toml")
    scenario = scenario_from(build_parser().parse_args(words))
    assert (scenario.behavior, scenario.formation, scenario.fish) == ("formation", "pyramid", 8)


@pytest.mark.slow
def test_the_playbook_copies_the_worlds_scenario_file_and_refuses_a_missing_one(
    tmp_path: Path, wheel: Path
) -> None:
    scenario = DEPLOY.parent / "experiments" / "formation.toml"
    path = inventory(tmp_path, wheel, fish_id=3, fishswarm_config=str(scenario), fishswarm_fish=8)
    result = ansible("ansible-playbook", "-i", str(path), "site.yml", "--check", "--diff")
    assert result.returncode == 0, result.stdout + result.stderr
    copied = result.stdout.split("Copy the swarm's scenario file")[1].split("TASK")[0]
    assert "changed: [localhost]" in copied
    assert "FISHSWARM_SCENARIO=--config /etc/fishswarm/scenario.toml --fish 8" in result.stdout
    missing = inventory(tmp_path, wheel, fish_id=3, fishswarm_config=str(tmp_path / "no.toml"))
    result = ansible("ansible-playbook", "-i", str(missing), "site.yml", "--check")
    assert result.returncode != 0
    assert "no.toml, which is not a file on the control node" in result.stdout


def test_the_roles_behaviours_are_fishswarms() -> None:
    import yaml

    # Asked of a fresh interpreter (tests register behaviours of their own in this one),
    # before it reads other packages' behaviours (a developer may have installed some).
    program = "from fishswarm.behaviors.registry import BEHAVIORS; print(*BEHAVIORS)"
    asked = subprocess.run(
        [sys.executable, "-c", program],
        capture_output=True, text=True, timeout=60, check=True,
    )  # fmt: skip
    behaviours = asked.stdout.split()
    defaults = yaml.safe_load((ROLE / "defaults" / "main.yml").read_text())
    assert defaults["fishswarm_behaviors"] == behaviours
    assert defaults["fishswarm_behavior"] in behaviours


@pytest.mark.slow
def test_a_replica_robot_is_given_its_learned_model(tmp_path: Path) -> None:
    words = _service_arguments(
        tmp_path, fishswarm_hardware="mock", fishswarm_behavior="replica",
        fishswarm_model="/lab/best_replica.npz",
    )  # fmt: skip
    args = build_parser().parse_args(words)
    assert args.behavior == "replica" and str(args.model) == "/etc/fishswarm/replica.npz"
    # With the world's scenario file, the model goes on top of it.
    words = _service_arguments(
        tmp_path, fishswarm_hardware="mock", fishswarm_config="/lab/replica.toml",
        fishswarm_model="/lab/best_replica.npz",
    )  # fmt: skip
    args = build_parser().parse_args(words)
    assert str(args.config) == "/etc/fishswarm/scenario.toml"
    assert str(args.model) == "/etc/fishswarm/replica.npz"


@pytest.mark.slow
def test_the_playbook_copies_a_learned_model_and_refuses_a_robot_that_could_not_run(
    tmp_path: Path, wheel: Path
) -> None:
    model = tmp_path / "best_replica.npz"
    model.write_bytes(b"weights")
    replica = {"fishswarm_behavior": "replica", "fishswarm_model": str(model)}
    path = inventory(tmp_path, wheel, fish_id=3, **replica)
    result = ansible("ansible-playbook", "-i", str(path), "site.yml", "--check", "--diff")
    assert result.returncode == 0, result.stdout + result.stderr
    copied = result.stdout.split("Copy the learned replica")[1].split("TASK")[0]
    assert "changed: [localhost]" in copied
    assert (
        "FISHSWARM_SCENARIO=--behavior replica --period 1.0 --model /etc/fishswarm/replica.npz"
        in (result.stdout)
    )
    # Three robots the play refuses, in one run, each with what to do: a misspelt
    # behaviour, a replica without a model, a model that is not there.
    common = {
        "ansible_connection": "local", "ansible_python_interpreter": sys.executable,
        "ansible_become": False, "fishswarm_hardware": "mock", "fishswarm_wheel": str(wheel),
        "fishswarm_router": "tcp/10.0.0.1:7447",
    }  # fmt: skip
    hosts = {
        "misspelt": {**common, "fish_id": 1, "fishswarm_behavior": "dispersal"},
        "no-model": {**common, "fish_id": 2, "fishswarm_behavior": "replica"},
        "missing-model": {
            **common, "fish_id": 3, "fishswarm_behavior": "replica",
            "fishswarm_model": str(tmp_path / "gone.npz"),
        },
        "model-of-none": {
            **common, "fish_id": 4, "fishswarm_behavior": "dispersion",
            "fishswarm_model": str(model),
        },
    }  # fmt: skip
    refused = tmp_path / "refused.yml"
    refused.write_text(json.dumps({"robots": {"hosts": hosts}}))
    result = ansible("ansible-playbook", "-i", str(refused), "site.yml", "--check")
    assert result.returncode != 0
    assert "fishswarm_behavior is dispersal: give one of dispersion, aggregation" in result.stdout
    assert "the replica behaviour needs a learned model: give fishswarm_model" in result.stdout
    assert "gone.npz, which is not a file on the control node" in result.stdout
    assert "fishswarm_model is a learned replica's, and fishswarm_behavior is dispersion" in (
        result.stdout
    )
    for host in hosts:
        assert re.search(
            rf"{host}\s+: ok=\d+\s+changed=0\s+unreachable=0\s+failed=1", result.stdout
        )


@pytest.mark.slow
def test_the_playbook_installs_a_behaviour_package_and_refuses_one_not_named(
    tmp_path: Path, wheel: Path, example_wheel: Path
) -> None:
    nearest = {
        "fishswarm_behavior": "nearest",
        "fishswarm_behavior_wheels": [str(example_wheel)],
        "fishswarm_extra_behaviors": ["nearest"],
    }
    path = inventory(tmp_path, wheel, fish_id=3, **nearest)
    result = ansible("ansible-playbook", "-i", str(path), "site.yml", "--check", "--diff")
    assert result.returncode == 0, result.stdout + result.stderr
    copied = result.stdout.split("Copy the wheels of behaviour packages")[1].split("TASK")[0]
    assert f"changed: [localhost] => (item={example_wheel})" in copied
    assert "FISHSWARM_SCENARIO=--behavior nearest --period 1.0" in result.stdout
    # The package's behaviour not named, its wheel not there: refused, with what to do.
    common = {
        "ansible_connection": "local", "ansible_python_interpreter": sys.executable,
        "ansible_become": False, "fishswarm_hardware": "mock", "fishswarm_wheel": str(wheel),
        "fishswarm_router": "tcp/10.0.0.1:7447",
    }  # fmt: skip
    hosts = {
        "unnamed": {
            **common, "fish_id": 1, "fishswarm_behavior": "nearest",
            "fishswarm_behavior_wheels": [str(example_wheel)],
        },
        "no-wheel": {
            **common, "fish_id": 2, "fishswarm_behavior_wheels": [str(tmp_path / "gone.whl")],
        },
    }  # fmt: skip
    refused = tmp_path / "refused.yml"
    refused.write_text(json.dumps({"robots": {"hosts": hosts}}))
    result = ansible("ansible-playbook", "-i", str(refused), "site.yml", "--check")
    assert result.returncode != 0
    assert (
        "fishswarm_behavior is nearest: give one of dispersion, aggregation, orbit, milling, "
        "waltz, replica, formation (a package's own behaviour: its wheel in "
        "fishswarm_behavior_wheels, its name in fishswarm_extra_behaviors)"
    ) in " ".join(result.stdout.split())
    assert "gone.whl, which is not a file on the control node" in result.stdout
    for host in hosts:
        assert re.search(
            rf"{host}\s+: ok=\d+\s+changed=0\s+unreachable=0\s+failed=1", result.stdout
        )


@pytest.mark.slow
def test_a_secured_robots_service_gives_its_certificates_folder(tmp_path: Path) -> None:
    plain = build_parser().parse_args(_service_arguments(tmp_path, fishswarm_hardware="mock"))
    assert plain.secure is None
    words = _service_arguments(
        tmp_path, fishswarm_hardware="mock", fishswarm_secure_dir="/home/lab/lab-keys",
        fishswarm_router="tls/10.0.0.1:7447",
    )  # fmt: skip
    at = words.index("--secure")
    assert words[at + 1] == "/etc/fishswarm/keys"
    # The robot's folder as the play fills it (ca.pem and its own pair): the robot takes it.
    from fishswarm.actors.security import init_secure

    keys = tmp_path / "keys"
    init_secure(keys, robots=[7])
    words[at + 1] = str(keys)
    secured = build_parser().parse_args(words)
    assert secured.secure == keys and secured.connect == "tls/10.0.0.1:7447"


@pytest.mark.slow
def test_the_playbook_gives_a_secured_robot_its_certificates_and_refuses_missing_ones(
    tmp_path: Path, wheel: Path
) -> None:
    from fishswarm.actors.security import init_secure

    keys = tmp_path / "lab-keys"
    init_secure(keys, robots=[3])
    secured = {"fishswarm_secure_dir": str(keys), "fishswarm_router": "tls/10.0.0.1:7447"}
    path = inventory(tmp_path, wheel, fish_id=3, **secured)
    result = ansible("ansible-playbook", "-i", str(path), "site.yml", "--check", "--diff")
    assert result.returncode == 0, result.stdout + result.stderr
    copied = result.stdout.split("Copy the authority's certificate")[1].split("TASK")[0]
    for name in ("ca.pem", "robot-3.pem", "robot-3.key"):
        assert f"changed: [localhost] => (item={name})" in copied
    assert "ca.key" not in result.stdout  # the authority's key stays on the base station
    assert "FISHSWARM_SECURE=--secure /etc/fishswarm/keys" in result.stdout
    # Two robots the play refuses, in one run: robot 4 has no certificate in the folder
    # (the play says how to make one); robot 3 is secured but given a plain router.
    refused = tmp_path / "refused.yml"
    common = {
        "ansible_connection": "local", "ansible_python_interpreter": sys.executable,
        "ansible_become": False, "fishswarm_hardware": "mock", "fishswarm_wheel": str(wheel),
        "fishswarm_secure_dir": str(keys),
    }  # fmt: skip
    hosts = {
        "no-certificate": {**common, "fish_id": 4, "fishswarm_router": "tls/10.0.0.1:7447"},
        "plain-router": {**common, "fish_id": 3, "fishswarm_router": "tcp/10.0.0.1:7447"},
    }
    refused.write_text(json.dumps({"robots": {"hosts": hosts}}))
    result = ansible("ansible-playbook", "-i", str(refused), "site.yml", "--check")
    assert result.returncode != 0
    assert "robot-4.pem is missing" in result.stdout
    assert f"fishswarm secure init {keys} --robots 4" in result.stdout
    assert "give fishswarm_router as tls/HOST:PORT" in result.stdout
    assert re.search(
        r"no-certificate\s+: ok=\d+\s+changed=\d+\s+unreachable=0\s+failed=1", result.stdout
    )
    assert re.search(
        r"plain-router\s+: ok=\d+\s+changed=\d+\s+unreachable=0\s+failed=1", result.stdout
    )


@pytest.mark.slow
def test_the_service_starts_the_robot_with_arguments_the_cli_accepts(tmp_path: Path) -> None:
    words = _service_arguments(tmp_path, fishswarm_hardware="mock")
    unit = (tmp_path / "fishswarm-fish@.service").read_text()
    args = build_parser().parse_args(words)
    assert (args.command, args.robot_id, args.hardware) == ("robot", 7, "mock")
    assert args.connect == "tcp/192.168.1.10:7447" and args.connect_timeout == -1
    assert args.control_period == 1.0  # the world's default period
    assert "Restart=on-failure" in unit
    assert "RestartPreventExitStatus=2" in unit.splitlines()  # a refused setting: no loop
    # lgpio makes its pipes in the working directory: one the robot's user may write.
    assert "RuntimeDirectory=fishswarm-%i" in unit.splitlines()
    assert "WorkingDirectory=/run/fishswarm-%i" in unit.splitlines()
    verify = shutil.which("systemd-analyze")
    if verify is not None:
        (tmp_path / "fishswarm-fish@.service").write_text(unit)
        checked = subprocess.run(
            [verify, "verify", str(tmp_path / "fishswarm-fish@7.service")],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        # Only the robot's venv is missing on this machine; every setting must be known.
        problems = [
            line
            for line in (checked.stdout + checked.stderr).splitlines()
            if line and "/opt/fishswarm/venv/bin/fishswarm is not executable" not in line
        ]
        assert problems == []
    client = render("zenoh-client.json5.j2", tmp_path, fishswarm_router="tcp/10.1.2.3:7447")
    config = zenoh.Config.from_file(str(tmp_path / "zenoh-client.json5"))
    assert config.get_json("connect/endpoints") == '["tcp/10.1.2.3:7447"]'
    assert config.get_json("scouting/multicast/enabled") == "false"
    assert "client" in client


BOOKWORM = ("numpy==1.24.2", "msgpack==1.0.3", "trio==0.22.0", "gpiozero==2.0", "smbus2==0.4.2")
"""The versions of the robot's Python packages in Raspberry Pi OS bookworm, which the role
installs with apt."""
OFFLINE = ("NewConnectionError", "Temporary failure in name resolution", "Network is unreachable")


def _assert_the_robot_drives(python: str, folder: Path) -> None:
    """The driver and the fish actor run on mock pins in ``python``'s environment, with none
    of the base station's packages importable."""
    from tests.test_robot_imports import BLOCKED, DRIVE

    driven = subprocess.run(
        [python, "-c", f"BLOCKED = {BLOCKED!r}\n" + DRIVE],
        capture_output=True, text=True, timeout=120, check=False, cwd=folder,
    )  # fmt: skip
    assert driven.returncode == 0, driven.stderr
    perceptions, commands, scipy_loaded = driven.stdout.split()
    assert int(perceptions) >= 4 and int(commands) >= 4 and scipy_loaded == "False"


def _robot_commands(
    python: str, argvs: list[list[str]], folder: Path
) -> subprocess.CompletedProcess[str]:
    """fishswarm's commands ``argvs`` run in ``python``'s environment, the base station's
    packages blocked; stdout ends with their exit codes."""
    from tests.test_robot_imports import BLOCKED, COMMANDS

    program = f"BLOCKED = {BLOCKED!r}\nARGVS = {argvs!r}\n" + COMMANDS
    return subprocess.run(
        [python, "-W", "ignore", "-c", program],
        capture_output=True, text=True, timeout=120, check=False, cwd=folder,
    )  # fmt: skip


@pytest.mark.slow
def test_the_robot_runs_on_the_packages_the_role_installs(tmp_path: Path, wheel: Path) -> None:
    # The venv the role makes on a robot, with pip's copies of bookworm's packages standing
    # in for apt's, what the role asks pip for, and the wheel without its dependencies.
    import yaml

    defaults = yaml.safe_load((ROLE / "defaults" / "main.yml").read_text())
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python = str(venv / "bin" / "python")

    def pip(*args: str) -> None:
        result = subprocess.run(
            [python, "-m", "pip", "install", "-q", "--disable-pip-version-check", *args],
            capture_output=True, text=True, timeout=600, check=False,
        )  # fmt: skip
        if result.returncode and any(sign in result.stderr for sign in OFFLINE):
            pytest.skip(f"pip cannot reach its package index here: {result.stderr[-300:]}")
        assert result.returncode == 0, result.stderr

    pip(*BOOKWORM, *defaults["fishswarm_pip_packages"])
    pip("--no-deps", str(wheel))
    # The driver and the fish actor on mock pins, and the robot's commands, with none of
    # the base station's packages importable.
    _assert_the_robot_drives(python, tmp_path)
    argvs = [["robot", "--help"], ["robot", "--id", "3", "--hardware", "bluebot"]]
    ran = _robot_commands(python, argvs, tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.split()[-2:] == ["0", "1"]
    assert "cannot open the BlueBot's hardware" in ran.stderr
    versions = subprocess.run(
        [python, "-c", "import numpy, msgpack, trio; print(numpy.__version__, trio.__version__)"],
        capture_output=True, text=True, timeout=60, check=True,
    )  # fmt: skip
    assert versions.stdout.split() == ["1.24.2", "0.22.0"]


INSTALL_ONLY = """- name: Install fishswarm as the role does, into the test's folder
  hosts: robots
  gather_facts: true
  tasks:
    - name: The role's install steps
      ansible.builtin.include_role:
        name: fishswarm
        tasks_from: install
"""


@pytest.mark.slow
def test_a_mock_robot_runs_from_what_the_role_installs(
    tmp_path: Path, wheel: Path, example_wheel: Path
) -> None:
    # The role's own install steps, run for real (not in check mode) into a folder of the
    # test's, on a machine whose Python has no site packages to lend: all a mock robot
    # needs must come from what the role installs. Before, it installed only Zenoh and the
    # wheel without its dependencies, and the robot's service failed on 'import trio'.
    home = tmp_path / "opt"
    playbook = tmp_path / "install.yml"
    playbook.write_text(INSTALL_ONLY)

    def install(behavior_wheels: list[str]) -> None:
        path = inventory(
            tmp_path,
            wheel,
            fish_id=3,
            fishswarm_home=str(home),
            fishswarm_python=getattr(sys, "_base_executable", sys.executable),
            fishswarm_system_site_packages=False,
            fishswarm_behavior_wheels=behavior_wheels,
        )
        result = ansible(
            "ansible-playbook", "-i", str(path), str(playbook), cwd=tmp_path,
            roles=DEPLOY / "roles",
        )  # fmt: skip
        if result.returncode and any(sign in result.stdout for sign in OFFLINE):
            pytest.skip(f"pip cannot reach its package index here: {result.stdout[-300:]}")
        assert result.returncode == 0, result.stdout + result.stderr

    def known_behaviors() -> list[str]:
        known = subprocess.run(
            [python, "-c", "from fishswarm.behaviors.registry import names; print(*names())"],
            capture_output=True, text=True, timeout=60, check=True, cwd=tmp_path,
        )  # fmt: skip
        return known.stdout.split()

    install([str(example_wheel)])
    python = str(home / "venv" / "bin" / "python")
    _assert_the_robot_drives(python, tmp_path)
    # The behaviour package is installed beside fishswarm, and its behaviour known there.
    assert known_behaviors()[-1] == "nearest"
    assert (home / "behavior-packages.txt").read_text() == "fishswarm_nearest\n"
    # Dropped from the list, the next play uninstalls it and removes its wheel; fishswarm's
    # own wheel stays.
    install([])
    assert "nearest" not in known_behaviors() and "formation" in known_behaviors()
    assert sorted(whl.name for whl in (home / "wheels").iterdir()) == [wheel.name]
    assert (home / "behavior-packages.txt").read_text() == "\n"
    # The robot's command as its service runs it: the mock pins open, then it looks for a
    # router (none here) and says so.
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    argvs = [["robot", "--id", "3", "--hardware", "mock", "--connect", endpoint,
              "--connect-timeout", "0.5"]]  # fmt: skip
    ran = _robot_commands(python, argvs, tmp_path)
    assert ran.returncode == 0, ran.stderr
    assert ran.stdout.split()[-1:] == ["1"]
    assert "cannot open a client session" in ran.stderr and "Traceback" not in ran.stderr
