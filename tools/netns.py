"""Test hosts on one machine: network namespaces joined by veth pairs to a bridge (docs/design.md
§6).

The papers assume lossless WiFi between the NAOs; to measure what real loss does we run
every process of a formation on its own "host". A host here is a Linux network namespace
``{prefix}-h{i}`` with one interface ``eth0`` holding ``10.77.0.{i}/24``. All ``eth0`` are
veth pairs whose other ends sit on a bridge ``br0`` inside a separate switch namespace
``{prefix}-sw``. Nothing is created in the caller's (host) network namespace, the /24
(``10.77.0.0/24``, RFC 1918) is routed only inside these namespaces, and no host has a
default route: traffic between test hosts never leaves the machine and cannot reach any
other address. Each host also has ``lo`` up and a multicast route on ``eth0`` so zenoh's
multicast scouting works between hosts if wanted.

Library use::

    with Fabric(3, prefix="nao") as fab:      # nao-h1..nao-h3, addresses 10.77.0.1..3
        proc = fab.popen(1, [sys.executable, "-m", "tools.router"])
        fab.run(2, ["ping", "-c", "1", fab.address(1)])

The context manager tears everything down on exit, also after an exception, and
:func:`cleanup` removes leftovers of a crashed run with the same prefix.

CLI: ``python -m tools.netns up --hosts 3 [--prefix nao]``, ``python -m tools.netns down
[--prefix nao]``, ``python -m tools.netns list``. Needs root and iproute2 (``ip``).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Mapping, Sequence
from types import TracebackType
from typing import IO, Any

SUBNET = "10.77.0.0/24"
SUBNET_PREFIX = "10.77.0."
MAX_HOSTS = 250
_PREFIX_RE = re.compile(r"^[a-z][a-z0-9]{0,7}$")


class NetnsError(RuntimeError):
    """A namespace operation that cannot be done; the text says why and what to do."""


def _check_prefix(prefix: str) -> str:
    if not _PREFIX_RE.match(prefix):
        raise ValueError(
            f"prefix {prefix!r} must be 1-8 lowercase letters/digits starting with a letter"
        )
    return prefix


def host_name(prefix: str, index: int) -> str:
    """Namespace name of host ``index`` (1-based)."""
    return f"{_check_prefix(prefix)}-h{index}"


def switch_name(prefix: str) -> str:
    """Namespace that holds the bridge."""
    return f"{_check_prefix(prefix)}-sw"


def address(index: int) -> str:
    """IPv4 address of host ``index`` (1-based) inside the test /24."""
    if not 1 <= index <= MAX_HOSTS:
        raise ValueError(f"host index {index} outside [1, {MAX_HOSTS}]")
    return f"{SUBNET_PREFIX}{index}"


def preflight() -> None:
    """Raise :class:`NetnsError` unless we are root and ``ip`` is installed."""
    if shutil.which("ip") is None:
        raise NetnsError("the 'ip' command (iproute2) is not installed: apt-get install iproute2")
    if os.geteuid() != 0:
        raise NetnsError("network namespaces need root (run as root or with sudo)")


_UNAVAILABLE: list[str | None] = []


def unavailable_reason() -> str | None:
    """Why test hosts cannot be made here (for pytest skips), or None when they can.

    Besides root and ``ip``, tries to create and delete one namespace: a root shell in a
    container without ``CAP_SYS_ADMIN``/``CAP_NET_ADMIN`` passes the first checks and
    still cannot. The answer is cached for the process.
    """
    if not _UNAVAILABLE:
        try:
            preflight()
            probe = f"naoprobe{os.getpid()}"
            made = _ip("netns", "add", probe, check=False)
            _ip("netns", "del", probe, check=False)
            reason = (
                None
                if made.returncode == 0
                else (f"cannot create a network namespace: {made.stderr.strip()}")
            )
        except NetnsError as exc:
            reason = str(exc)
        _UNAVAILABLE.append(reason)
    return _UNAVAILABLE[0]


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run(["ip", *args], capture_output=True, text=True, check=False)
    if check and proc.returncode != 0:
        raise NetnsError(f"ip {' '.join(args)} failed: {proc.stderr.strip() or proc.returncode}")
    return proc


def list_namespaces() -> list[str]:
    """Names of all network namespaces (``ip netns list``)."""
    out = _ip("netns", "list").stdout
    return sorted(line.split()[0] for line in out.splitlines() if line.strip())


def exists(name: str) -> bool:
    return name in list_namespaces()


def netns_cmd(name: str, argv: Sequence[str]) -> list[str]:
    """The argv that runs ``argv`` inside namespace ``name``."""
    return ["ip", "netns", "exec", name, *argv]


def cleanup(prefix: str) -> list[str]:
    """Delete every namespace ``{prefix}-h*`` and ``{prefix}-sw`` (their veths go with them).

    Processes still running inside are killed first so the namespaces really go away.
    Returns the names deleted.
    """
    _check_prefix(prefix)
    pat = re.compile(rf"^{re.escape(prefix)}-(h\d+|sw)$")
    gone: list[str] = []
    for name in list_namespaces():
        if not pat.match(name):
            continue
        pids = _ip("netns", "pids", name, check=False).stdout.split()
        for pid in pids:
            if pid.isdigit():
                with contextlib.suppress(ProcessLookupError):
                    os.kill(int(pid), 9)
        _ip("netns", "del", name, check=False)
        gone.append(name)
    return gone


class Fabric:
    """``n`` hosts on one bridge; a context manager that always cleans up.

    Host indices are 1-based; host ``i`` is namespace ``{prefix}-h{i}`` at ``10.77.0.{i}``.
    Creating a fabric whose namespaces already exist (a crashed earlier run) first removes
    them. Processes started with :meth:`popen` are terminated on exit.
    """

    def __init__(self, n: int, prefix: str = "nao") -> None:
        if not 1 <= n <= MAX_HOSTS:
            raise ValueError(f"number of hosts {n} outside [1, {MAX_HOSTS}]")
        self.n = n
        self.prefix = _check_prefix(prefix)
        self._procs: list[subprocess.Popen[Any]] = []
        self._up = False

    # ------------------------------------------------------------------ naming
    def name(self, index: int) -> str:
        self._check_index(index)
        return host_name(self.prefix, index)

    def address(self, index: int) -> str:
        self._check_index(index)
        return address(index)

    @property
    def hosts(self) -> list[str]:
        return [host_name(self.prefix, i) for i in range(1, self.n + 1)]

    def _check_index(self, index: int) -> None:
        if not 1 <= index <= self.n:
            raise ValueError(f"host index {index} outside [1, {self.n}]")

    # ------------------------------------------------------------------ lifecycle
    def up(self) -> Fabric:
        preflight()
        cleanup(self.prefix)
        sw = switch_name(self.prefix)
        try:
            _ip("netns", "add", sw)
            _ip("-n", sw, "link", "set", "lo", "up")
            _ip("-n", sw, "link", "add", "br0", "type", "bridge")
            _ip("-n", sw, "link", "set", "br0", "up")
            for i in range(1, self.n + 1):
                ns = host_name(self.prefix, i)
                _ip("netns", "add", ns)
                # Both ends are born inside their namespaces: nothing touches the host's.
                _ip(
                    "-n", sw, "link", "add", f"p{i}", "type", "veth",
                    "peer", "name", "eth0", "netns", ns,
                )  # fmt: skip
                _ip("-n", sw, "link", "set", f"p{i}", "master", "br0")
                _ip("-n", sw, "link", "set", f"p{i}", "up")
                _ip("-n", ns, "link", "set", "lo", "up")
                _ip("-n", ns, "addr", "add", f"{address(i)}/24", "dev", "eth0")
                _ip("-n", ns, "link", "set", "eth0", "up")
                _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")
        except BaseException:
            cleanup(self.prefix)
            raise
        self._up = True
        return self

    def down(self) -> None:
        for proc in self._procs:
            stop(proc)
        self._procs.clear()
        cleanup(self.prefix)
        self._up = False

    def __enter__(self) -> Fabric:
        return self.up()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.down()

    # ------------------------------------------------------------------ processes
    def run(
        self, index: int, argv: Sequence[str], timeout: float = 30.0, check: bool = True
    ) -> subprocess.CompletedProcess[str]:
        """Run ``argv`` to completion inside host ``index``; output captured as text."""
        proc = subprocess.run(
            netns_cmd(self.name(index), argv),
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
        if check and proc.returncode != 0:
            raise NetnsError(
                f"{' '.join(argv)} in {self.name(index)} exited {proc.returncode}: "
                f"{proc.stderr.strip()[-500:]}"
            )
        return proc

    def popen(
        self,
        index: int,
        argv: Sequence[str],
        stdout: int | IO[Any] | None = subprocess.PIPE,
        stderr: int | IO[Any] | None = None,
        env: Mapping[str, str] | None = None,
        cwd: str | None = None,
    ) -> subprocess.Popen[str]:
        """Start ``argv`` inside host ``index``; it is stopped when the fabric goes down."""
        proc = subprocess.Popen(
            netns_cmd(self.name(index), argv),
            stdout=stdout,
            stderr=stderr,
            text=True,
            env=dict(env) if env is not None else None,
            cwd=cwd,
            start_new_session=True,
        )
        self._procs.append(proc)
        return proc


def stop(proc: subprocess.Popen[Any], timeout: float = 5.0) -> int | None:
    """SIGTERM ``proc`` (and its session), then SIGKILL after ``timeout``; its exit code."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, 15)
        except (ProcessLookupError, PermissionError):
            proc.terminate()
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            try:
                os.killpg(proc.pid, 9)
            except (ProcessLookupError, PermissionError):
                proc.kill()
            proc.wait(timeout=timeout)
    return proc.returncode


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.netns", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p_up = sub.add_parser("up", help="create hosts PREFIX-h1..hN on a bridge")
    p_up.add_argument("--hosts", type=int, required=True)
    p_up.add_argument("--prefix", default="nao")
    p_down = sub.add_parser("down", help="delete the hosts and the bridge of PREFIX")
    p_down.add_argument("--prefix", default="nao")
    sub.add_parser("list", help="list network namespaces")
    args = ap.parse_args(argv)
    try:
        preflight()
        if args.cmd == "up":
            fab = Fabric(args.hosts, args.prefix).up()
            for i in range(1, fab.n + 1):
                print(f"{fab.name(i)} {fab.address(i)}")
            print(
                f"bridge in {switch_name(fab.prefix)}; remove with: python -m tools.netns down --prefix {fab.prefix}"
            )
        elif args.cmd == "down":
            gone = cleanup(args.prefix)
            print("deleted: " + (" ".join(gone) if gone else "nothing"))
        else:
            print("\n".join(list_namespaces()))
    except (NetnsError, ValueError) as exc:
        print(f"netns: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
