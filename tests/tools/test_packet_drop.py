"""tools.packet_drop: argument checks everywhere, real iptables rules in a namespace as root."""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from tools import netns, packet_drop
from tools.packet_drop import Dropper, PacketDropError

#: root, iptables and network namespaces: skipped without them, failed under CI=1
needs_root = pytest.mark.usefixtures("netns_hosts")
PREFIX = f"pd{os.getpid() % 100000}"


# ---------------------------------------------------------------- checks without root


def test_missing_test_hosts_skip_here_and_fail_in_ci() -> None:
    from tests.conftest import require_hosts

    require_hosts(None, ci=True)  # available: the test runs
    with pytest.raises(pytest.skip.Exception, match="no iptables"):
        require_hosts("no iptables", ci=False)
    with pytest.raises(pytest.fail.Exception, match=r"CI: .*no iptables"):
        require_hosts("no iptables", ci=True)


def test_current_namespace_needs_the_here_guard() -> None:
    with pytest.raises(ValueError, match="needs --here"):
        Dropper(None)


def test_netns_and_here_are_exclusive() -> None:
    with pytest.raises(ValueError, match="not both"):
        Dropper("x", here=True)


@pytest.mark.parametrize("loss", [-0.1, 1.5, 20.0])
def test_loss_outside_unit_interval(loss: float) -> None:
    with pytest.raises(ValueError, match="outside"):
        Dropper("x").install(loss)


def test_bad_direction() -> None:
    with pytest.raises(ValueError, match="direction"):
        Dropper("x").install(0.1, direction="sideways")


def test_bad_port() -> None:
    with pytest.raises(ValueError, match="port"):
        Dropper("x").install(0.1, port=70000)


def test_bad_exempt_address() -> None:
    with pytest.raises(ValueError, match="exempt address"):
        Dropper("x").install(0.1, exempt=["no-such-host.invalid"])


def test_bad_exempt_port() -> None:
    with pytest.raises(ValueError, match="port 0 outside"):
        Dropper("x").install(0.1, exempt_ports=[0])


def test_exempt_host_name_is_resolved() -> None:
    assert packet_drop._check_addr("localhost") == "127.0.0.1/32"
    assert packet_drop._check_addr("10.77.0.0/24") == "10.77.0.0/24"


def test_cli_needs_exactly_one_action(capsys: pytest.CaptureFixture[str]) -> None:
    assert packet_drop.main(["--netns", "x"]) == 2
    assert packet_drop.main(["--netns", "x", "--clear", "--show"]) == 2
    assert "exactly one" in capsys.readouterr().err


def test_cli_without_netns_or_here_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert packet_drop.main(["--loss", "0.2"]) == 1
    assert "--here" in capsys.readouterr().err


def test_not_root_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(packet_drop.os, "geteuid", lambda: 1000)
    monkeypatch.setattr(packet_drop.shutil, "which", lambda name: f"/usr/sbin/{name}")
    with pytest.raises(PacketDropError, match="root"):
        Dropper("x").preflight()


def test_missing_iptables_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(packet_drop.shutil, "which", lambda name: None)
    with pytest.raises(PacketDropError, match="iptables is not installed"):
        Dropper("x").preflight()


# ---------------------------------------------------------------- real rules (root)


def _iptables_s(host: str) -> str:
    return subprocess.run(
        netns.netns_cmd(host, ["iptables", "-S"]), capture_output=True, text=True, check=True
    ).stdout


@pytest.fixture
def host() -> object:
    with netns.Fabric(1, prefix=PREFIX) as fab:
        yield fab.name(1)


@needs_root
@pytest.mark.netns
def test_missing_namespace_is_a_clear_error() -> None:
    with pytest.raises(PacketDropError, match="does not exist"):
        Dropper(f"{PREFIX}-nosuch").install(0.1)


@needs_root
@pytest.mark.netns
def test_install_is_idempotent_and_clear_removes_all(host: str) -> None:
    d = Dropper(host)
    d.install(0.25, direction="both", port=7447)
    d.install(0.25, direction="both", port=7447)
    rows = d.counters()
    # one tcp + one udp rule per direction, not doubled by the second install
    assert sorted((r.direction, r.rule.split()[0]) for r in rows) == [
        ("in", "17"), ("in", "6"), ("out", "17"), ("out", "6"),
    ]  # fmt: skip
    assert all("multiport ports 7447" in r.rule and "0.25" in r.rule for r in rows)
    save = _iptables_s(host)
    assert save.count("-j NAO_DROP_IN") == 1 and save.count("-j NAO_DROP_OUT") == 1
    # a new install replaces the old one
    d.install(0.5, direction="in")
    rows = d.counters()
    assert [r.direction for r in rows] == ["in"] and "0.5" in rows[0].rule
    assert d.clear() is True
    assert d.counters() == []
    assert d.clear() is False  # clearing nothing is fine
    assert "NAO_DROP" not in _iptables_s(host)


@needs_root
@pytest.mark.netns
def test_loss_one_drops_everything_and_counts(host: str) -> None:
    d = Dropper(host)
    d.install(1.0, direction="out")
    # every datagram leaves through OUTPUT and is dropped (sendto then fails with EPERM)
    script = (
        "import socket\ns = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n"
        "for _ in range(5):\n"
        "    try:\n        s.sendto(b'x', ('10.77.0.1', 9))\n"
        "    except PermissionError:\n        pass\n"
    )
    proc = subprocess.run(
        netns.netns_cmd(host, ["python3", "-c", script]), capture_output=True, timeout=30
    )
    assert proc.returncode == 0, proc.stderr
    assert d.dropped_packets() == 5


def _send_udp(host: str, dests: list[tuple[str, int]]) -> None:
    """One datagram to each (address, port) from inside ``host``."""
    script = (
        "import socket, sys\ns = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n"
        f"for dst in {dests!r}:\n"
        "    try:\n        s.sendto(b'x', dst)\n"
        "    except OSError:\n        pass\n"
    )
    proc = subprocess.run(
        netns.netns_cmd(host, ["python3", "-c", script]), capture_output=True, timeout=30
    )
    assert proc.returncode == 0, proc.stderr


@needs_root
@pytest.mark.netns
def test_exempt_address_is_never_dropped(host: str) -> None:
    d = Dropper(host)
    d.install(1.0, direction="out", exempt=["10.77.0.1"])
    _send_udp(host, [("10.77.0.1", 9)] * 4 + [("10.77.0.9", 9)] * 3)
    # only the three datagrams to the non-exempt address were dropped
    assert d.dropped_packets() == 3
    assert "-d 10.77.0.1/32 -j RETURN" in _iptables_s(host)


@needs_root
@pytest.mark.netns
def test_exempt_port_is_never_dropped(host: str) -> None:
    d = Dropper(host)
    d.install(1.0, direction="out", exempt_ports=[7448])
    _send_udp(host, [("10.77.0.9", 7448)] * 4 + [("10.77.0.9", 7447)] * 3)
    # only the three datagrams to the robot-to-robot port were dropped
    assert d.dropped_packets() == 3
    assert "-p tcp -m multiport --ports 7448 -j RETURN" in _iptables_s(host)


@needs_root
@pytest.mark.netns
def test_cli_show_json(host: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert packet_drop.main(["--netns", host, "--loss", "0.2", "--direction", "in"]) == 0
    capsys.readouterr()
    assert packet_drop.main(["--netns", host, "--show", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 1 and rows[0]["direction"] == "in" and rows[0]["packets"] == 0
    assert packet_drop.main(["--netns", host, "--clear"]) == 0
    assert "cleared" in capsys.readouterr().out
