"""Random packet loss inside a network namespace (docs/design.md §6 fault injection).

The NAO paper (4.1.2) exchanges every neighbour record once over WiFi it assumes lossless;
this tool makes the link lossy so we can measure what the exchange-until-agreement
protocol costs. It uses ``iptables -m statistic --mode random --probability P -j DROP``
(``tc netem`` needs ``sch_netem``, which some kernels lack). Dropped packets are real
losses at the IP layer: over TCP they become retransmissions and delay, over UDP they
are gone.

Rules live in two chains of our own, ``NAO_DROP_IN`` (jumped to from ``INPUT``) and
``NAO_DROP_OUT`` (from ``OUTPUT``), each rule tagged with the comment ``nao-packet-drop``.
Installing flushes our chains and writes them again, so running the same command twice
gives the same rules (idempotent); ``--clear`` removes the jumps and the chains, and is
a no-op when nothing is installed. ``--direction both`` drops with probability P on the
way in *and* on the way out, so a packet crossing two such hosts meets up to two draws.
With ``--port`` only TCP and UDP packets whose source or destination port is that port
are dropped; without it every IP packet is subject. Note that zenoh peers which meet
through a router (gossip) also open direct links to each other on ephemeral ports: a
``--port 7447`` rule only hits the links to the router, so to make a host lossy as a
whole (what ``tools.eval_loss`` does) give no port.

``--exempt ADDR`` (repeatable; an address, a network or a host name such as the
compose service ``world``) spares the traffic to and from one peer: in the
project's loss evaluation the world host is exempt, because on a real NAO the camera and
the legs are on board and only the robot-to-robot exchange crosses WiFi.

``--exempt-port PORT`` (repeatable) spares TCP and UDP packets whose source or
destination port is ``PORT``. Behind a router every agent link goes to the router, so an
address cannot tell world traffic from robot-to-robot traffic; the router's second port
(``agent.wire.WORLD_PORT``, 7448) carries the world's link and the agents' body
sessions, and ``--exempt-port 7448`` spares exactly that (what ``tools.eval_loss`` and
the compose ``LOSS`` setting do).

By default the tool acts inside ``--netns NAME``. Acting on the caller's own network
namespace needs ``--here`` as a guard, because a lossy host namespace breaks everything
else on the machine.

Examples::

    python -m tools.packet_drop --netns nao-h2 --loss 0.2 --direction in --port 7447
    python -m tools.packet_drop --netns nao-h4 --loss 0.3 --exempt-port 7448
    python -m tools.packet_drop --netns nao-h2 --show          # rules + packet counters
    python -m tools.packet_drop --netns nao-h2 --show --json   # same, machine-readable
    python -m tools.packet_drop --netns nao-h2 --clear
"""

from __future__ import annotations

import argparse
import ipaddress
import json
import os
import shutil
import socket
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass

CHAINS = {"in": ("NAO_DROP_IN", "INPUT"), "out": ("NAO_DROP_OUT", "OUTPUT")}
COMMENT = "nao-packet-drop"
DIRECTIONS = ("in", "out", "both")


class PacketDropError(RuntimeError):
    """The rules cannot be installed, shown or cleared; the text says why."""


@dataclass(frozen=True)
class RuleCounter:
    """One DROP rule of ours and how many packets/bytes it has dropped so far."""

    direction: str
    chain: str
    packets: int
    bytes: int
    rule: str


def _directions(direction: str) -> tuple[str, ...]:
    if direction not in DIRECTIONS:
        raise ValueError(f"direction {direction!r} must be one of {', '.join(DIRECTIONS)}")
    return ("in", "out") if direction == "both" else (direction,)


def _check_loss(loss: float) -> float:
    if not isinstance(loss, int | float) or isinstance(loss, bool):
        raise ValueError(f"loss must be a number, got {type(loss).__name__}")
    if not 0.0 <= float(loss) <= 1.0:
        raise ValueError(f"loss {loss} outside [0, 1] (it is a probability, not a percent)")
    return float(loss)


def _check_addr(addr: str) -> str:
    """An IPv4 address/network as iptables wants it; a host name is resolved (containers)."""
    try:
        return str(ipaddress.ip_network(addr, strict=False))
    except ValueError:
        pass
    try:
        infos = socket.getaddrinfo(addr, None, socket.AF_INET)
    except (socket.gaierror, UnicodeError):
        raise ValueError(
            f"exempt address {addr!r} is not an IPv4 address, network or resolvable host name"
        ) from None
    return f"{sorted({str(i[4][0]) for i in infos})[0]}/32"


def _check_port(port: int | None) -> int | None:
    if port is not None and not 1 <= port <= 65535:
        raise ValueError(f"port {port} outside [1, 65535]")
    return port


class Dropper:
    """iptables DROP rules in one network namespace (``netns=None``: the caller's own)."""

    def __init__(self, netns: str | None, here: bool = False) -> None:
        if netns is None and not here:
            raise ValueError(
                "no --netns given: acting on this process's own network namespace needs --here"
            )
        if netns is not None and here:
            raise ValueError("give either --netns NAME or --here, not both")
        self.netns = netns

    # ------------------------------------------------------------------ plumbing
    def preflight(self) -> None:
        if shutil.which("iptables") is None:
            raise PacketDropError("iptables is not installed: apt-get install iptables")
        if os.geteuid() != 0:
            raise PacketDropError("iptables rules need root (run as root or with sudo)")
        if self.netns is not None:
            if shutil.which("ip") is None:
                raise PacketDropError("the 'ip' command (iproute2) is not installed")
            out = subprocess.run(
                ["ip", "netns", "list"], capture_output=True, text=True, check=False
            ).stdout
            names = {line.split()[0] for line in out.splitlines() if line.strip()}
            if self.netns not in names:
                raise PacketDropError(
                    f"network namespace {self.netns!r} does not exist "
                    f"(have: {', '.join(sorted(names)) or 'none'})"
                )

    def _ipt(self, *args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
        argv = ["iptables", "-w", "5", *args]
        if self.netns is not None:
            argv = ["ip", "netns", "exec", self.netns, *argv]
        proc = subprocess.run(argv, capture_output=True, text=True, check=False)
        if check and proc.returncode != 0:
            where = f"in {self.netns}" if self.netns else "here"
            raise PacketDropError(
                f"iptables {' '.join(args)} {where} failed: {proc.stderr.strip() or proc.returncode}"
            )
        return proc

    def _chain_exists(self, chain: str) -> bool:
        return self._ipt("-n", "-L", chain, check=False).returncode == 0

    # ------------------------------------------------------------------ operations
    def install(
        self,
        loss: float,
        direction: str = "both",
        port: int | None = None,
        exempt: Sequence[str] = (),
        exempt_ports: Sequence[int] = (),
    ) -> None:
        """Drop each packet with probability ``loss`` in ``direction``; replaces earlier rules.

        Packets from (in) or to (out) an address in ``exempt``, and TCP/UDP packets from
        or to a port in ``exempt_ports``, are never dropped.
        """
        p = _check_loss(loss)
        dirs = _directions(direction)
        _check_port(port)
        spared = [_check_addr(a) for a in exempt]
        spared_ports = [str(_check_port(int(x))) for x in exempt_ports]
        self.preflight()
        self.clear()
        for d in dirs:
            chain, parent = CHAINS[d]
            self._ipt("-N", chain)
            for addr in spared:
                self._ipt("-A", chain, "-s" if d == "in" else "-d", addr, "-j", "RETURN")
            for sp in spared_ports:
                for proto in ("tcp", "udp"):
                    self._ipt(
                        "-A", chain, "-p", proto, "-m", "multiport", "--ports", sp, "-j", "RETURN"
                    )
            if p > 0.0:
                stat = ["-m", "statistic", "--mode", "random", "--probability", f"{p:.6f}"]
                tag = ["-m", "comment", "--comment", COMMENT]
                if port is None:
                    self._ipt("-A", chain, *stat, *tag, "-j", "DROP")
                else:
                    for proto in ("tcp", "udp"):
                        self._ipt(
                            "-A", chain, "-p", proto, "-m", "multiport", "--ports", str(port),
                            *stat, *tag, "-j", "DROP",
                        )  # fmt: skip
            self._ipt("-I", parent, "1", "-j", chain)

    def clear(self) -> bool:
        """Remove our jumps and chains; True when something was installed."""
        self.preflight()
        found = False
        for chain, parent in CHAINS.values():
            while self._ipt("-C", parent, "-j", chain, check=False).returncode == 0:
                self._ipt("-D", parent, "-j", chain)
                found = True
            if self._chain_exists(chain):
                self._ipt("-F", chain)
                self._ipt("-X", chain)
                found = True
        return found

    def counters(self) -> list[RuleCounter]:
        """Our DROP rules with their packet/byte counters (empty when none installed)."""
        self.preflight()
        out: list[RuleCounter] = []
        for d, (chain, _parent) in CHAINS.items():
            if not self._chain_exists(chain):
                continue
            text = self._ipt("-n", "-v", "-x", "-L", chain).stdout
            for line in text.splitlines()[2:]:
                cols = line.split()
                if len(cols) < 3 or cols[2] != "DROP":
                    continue
                out.append(
                    RuleCounter(
                        direction=d,
                        chain=chain,
                        packets=int(cols[0]),
                        bytes=int(cols[1]),
                        rule=" ".join(cols[3:]),
                    )
                )
        return out

    def dropped_packets(self) -> int:
        """Total packets dropped by our rules so far."""
        return sum(c.packets for c in self.counters())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m tools.packet_drop",
        description="Random packet loss with iptables inside a network namespace.",
    )
    ap.add_argument("--netns", help="network namespace to act in (see tools.netns)")
    ap.add_argument("--here", action="store_true", help="act on this process's own namespace")
    ap.add_argument("--loss", type=float, help="drop probability in [0, 1] per direction")
    ap.add_argument("--direction", default="both", choices=DIRECTIONS)
    ap.add_argument("--port", type=int, help="only TCP/UDP packets from or to this port")
    ap.add_argument(
        "--exempt", action="append", default=[], help="never drop traffic with this address"
    )
    ap.add_argument(
        "--exempt-port",
        type=int,
        action="append",
        default=[],
        help="never drop TCP/UDP traffic from or to this port (the router's world port)",
    )
    ap.add_argument("--clear", action="store_true", help="remove the rules")
    ap.add_argument("--show", action="store_true", help="print rules and packet counters")
    ap.add_argument("--json", action="store_true", help="with --show: print JSON")
    args = ap.parse_args(argv)
    actions = sum([args.loss is not None, args.clear, args.show])
    if actions != 1:
        print("packet_drop: give exactly one of --loss P, --clear, --show", file=sys.stderr)
        return 2
    try:
        dropper = Dropper(args.netns, here=args.here)
        where = args.netns or "this namespace"
        if args.clear:
            found = dropper.clear()
            print(f"cleared packet-drop rules in {where}" if found else f"no rules in {where}")
        elif args.show:
            rows = dropper.counters()
            if args.json:
                print(json.dumps([asdict(r) for r in rows]))
            elif not rows:
                print(f"no packet-drop rules in {where}")
            else:
                for r in rows:
                    print(f"{r.direction:3s} {r.packets:10d} pkts {r.bytes:12d} bytes  {r.rule}")
        else:
            dropper.install(args.loss, args.direction, args.port, args.exempt, args.exempt_port)
            scope = f"port {args.port} (tcp+udp)" if args.port else "all packets"
            spared = [*args.exempt, *(f"port {x}" for x in args.exempt_port)]
            if spared:
                scope += f" except {', '.join(spared)}"
            print(f"installed loss {args.loss:g} direction {args.direction} on {scope} in {where}")
    except (PacketDropError, ValueError) as exc:
        print(f"packet_drop: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
