"""Fleet credentials (docs/design.md §8): create them, show them, hand them out per host.

    python -m tools.fleet init --robots 3 --out fleet/          # CA + robot-1..3, world,
                                                                 # observer, router, operator
    python -m tools.fleet init --ids 2,5,9 --host router.lab --out fleet/
    python -m tools.fleet show fleet/                           # the roster, checked
    python -m tools.fleet export fleet/ --identity robot-2 --out robot-2/   # one host's set
    python -m tools.fleet revoke fleet/ --robot 3 --reason key-compromise   # withdraw keys
    python -m tools.fleet revoke fleet/ --identity observer --identity robot-4
    python -m tools.fleet export fleet/ --identity operator --out operator/
    python -m tools.fleet reshape --shape line --credentials operator/ --fleet-size 8 \
        --connect tls/ROUTER:7447                           # the fleet holding: take a line

``export`` copies the public part (``ca.pem``, ``certs/``, ``crl.pem``) and exactly one
private key: that is what one host gets. The CA's private key (``ca-private/``) never
leaves the machine that made the fleet. ``revoke`` (which needs that key) adds
certificates to ``crl.pem``, the revocation list signed by the CA; revoking one again
changes nothing. Hand the new ``crl.pem`` to every host (docs/security.md "Revoking a
key"). See ``agent/wire/trust.py`` for the layout and the checks.

``reshape`` (docs/formation.md "Reshaping"): once every robot of the fleet (``--fleet-size``
of them, started with ``--reshape-wait``) is ``done`` on one plan, publish the operator's
signed command to take the shape of ``--shape NAME|FILE`` (repeat it: one shape after
the other), wait until the fleet holds it, and print each transition's outcome, sim and
wall time. It signs with the ``operator`` key of ``--credentials`` (a robot's key may not
command: the router refuses it, and every agent too). Exit 0 when every shape is held,
1 otherwise.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

from agent.wire import add_network_arguments
from agent.wire.trust import (
    REASONS,
    Credentials,
    FleetPaths,
    Identity,
    TrustError,
    create_fleet,
    revoke,
)


def _ids(args: argparse.Namespace) -> list[int]:
    if args.ids:
        try:
            return sorted({int(t) for t in args.ids.split(",") if t.strip()})
        except ValueError:
            raise ValueError(f"--ids {args.ids!r}: expected integers like 1,2,5") from None
    if args.robots is None or args.robots < 1:
        raise ValueError("give --robots N (ids 1..N) or --ids 1,2,5")
    return list(range(1, args.robots + 1))


def export(src: Path, who: Identity, out: Path) -> FleetPaths:
    """Copy the public credentials (with the revocation list, if any) and ``who``'s private
    key from ``src`` to ``out``; a revoked ``who`` is refused."""
    creds = Credentials(src)  # checks the source before copying anything
    creds.check_active(who)
    key = creds.paths.key(who)
    if not key.is_file():
        raise ValueError(f"{src} holds no private key for {who.cn}")
    dst = FleetPaths(out)
    if dst.ca.exists():
        raise ValueError(f"{out} already holds credentials")
    dst.certs.mkdir(parents=True, exist_ok=True)
    shutil.copy2(creds.paths.ca, dst.ca)
    if creds.paths.crl.is_file():
        shutil.copy2(creds.paths.crl, dst.crl)
    for cert in sorted(creds.paths.certs.glob("*.pem")):
        shutil.copy2(cert, dst.certs / cert.name)
    dst.keys.mkdir(parents=True, exist_ok=True)
    shutil.copy2(key, dst.key(who))
    dst.key(who).chmod(0o600)
    return dst


def _revoked_identities(args: argparse.Namespace) -> list[Identity]:
    who = {Identity.robot(r) for r in args.robot} | {Identity.parse(c) for c in args.identity}
    if not who:
        raise ValueError("name what to revoke: --robot N or --identity robot-N|world|observer")
    return sorted(who)


def reshape_command(args: argparse.Namespace) -> int:
    """``reshape``: drive :class:`tools.lib.reshape.Reshaper` over the operator's own bus."""
    from agent.config import load_shape
    from agent.net.bus import Bus, BusError
    from agent.wire import KEY_RESHAPE, KEY_STATUS_ALL, StatusMsg, id_from_key, network_spec
    from tools.lib.reshape import Reshaper, Seen

    try:
        shapes = [load_shape(s) for s in args.shape]
        for shape in shapes:
            shape.check_fleet(args.fleet_size)
        spec = network_spec(args, "operator")
        bus = Bus(spec)
    except (ValueError, BusError) as exc:
        print(f"fleet reshape: {exc}", file=sys.stderr)
        return 2
    seen: dict[int, Seen] = {}
    with bus:
        bus.subscribe(KEY_STATUS_ALL)
        op = Reshaper(
            shapes,
            [],
            lambda msg: bus.publish(KEY_RESHAPE, msg, "reshape"),
            timeout=args.timeout,
        )
        t0 = time.monotonic()
        while op.pending:
            for ev in bus.drain(0.2):
                if isinstance(ev.msg, StatusMsg) and id_from_key(ev.key) == ev.msg.sender:
                    m = ev.msg
                    seen[m.sender] = Seen(m.phase, m.plan_digest, m.t_sim, m.detail, m.error)
            if len(seen) >= args.fleet_size:  # the fleet: the robots heard, all of them
                op.robots = sorted(seen)
            if op.robots:
                op.step(time.monotonic() - t0, seen)
        bus.drain(0.5)  # the last re-send out before the session closes
    for t in op.done:
        print(
            f"reshape {t.command} to {t.shape}: {t.outcome} ({t.detail}); "
            f"sim {t.sim_s:.1f} s, wall {t.wall_s:.1f} s, sent {t.sends}x"
        )
    return 0 if op.ok else 1


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.fleet", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    i = sub.add_parser("init", help="create a fleet CA and every identity's key and certificate")
    i.add_argument("--robots", type=int, default=None, help="robot ids 1..N")
    i.add_argument("--ids", default="", help="robot ids, comma-separated (instead of --robots)")
    i.add_argument("--host", action="append", default=[], help="a name the router is reached at")
    i.add_argument("--days", type=int, default=365, help="certificate validity (days)")
    i.add_argument("--out", required=True, help="new folder for the credentials")
    s = sub.add_parser("show", help="check a credentials folder and list its roster")
    s.add_argument("dir")
    e = sub.add_parser("export", help="one host's credentials: public part + one private key")
    e.add_argument("dir")
    e.add_argument("--identity", required=True, help="robot-N, world, observer, router or operator")
    e.add_argument("--out", required=True)
    r = sub.add_parser("revoke", help="withdraw identities' certificates (needs the CA's key)")
    r.add_argument("dir")
    r.add_argument("--robot", type=int, action="append", default=[], help="robot id (repeat)")
    r.add_argument(
        "--identity", action="append", default=[], help="robot-N, world, observer or router"
    )
    r.add_argument(
        "--reason", choices=sorted(REASONS), default="unspecified", help="RFC 5280 reason"
    )
    o = sub.add_parser("reshape", help="command the fleet holding a shape to take another")
    o.add_argument("--shape", action="append", required=True, help="NAME|FILE (repeat)")
    o.add_argument("--fleet-size", type=int, required=True, help="robots in the fleet")
    o.add_argument("--timeout", type=float, default=900.0, help="s per transition")
    add_network_arguments(o, ("peer", "client"))
    args = p.parse_args(argv)
    if args.cmd == "reshape":
        return reshape_command(args)
    try:
        if args.cmd == "init":
            paths = create_fleet(args.out, _ids(args), hosts=args.host, valid_days=args.days)
            creds = Credentials(paths.root)
            print(
                f"fleet created in {paths.root}: robots {creds.robots()}, world, observer, "
                f"router, operator; keep {paths.ca_key} offline"
            )
        elif args.cmd == "show":
            creds = Credentials(args.dir)
            print(f"fleet CA {creds.paths.ca}")
            for who in sorted(creds.roster):
                own = "key here" if creds.paths.key(who).is_file() else "certificate only"
                print(f"  {who.cn:12s} {own}")
            for who, gone in sorted(creds.revoked.items()):
                print(f"  {who.cn:12s} revoked ({gone.describe()})")
        elif args.cmd == "revoke":
            want = _revoked_identities(args)
            added = revoke(args.dir, want, reason=args.reason)
            again = [w.cn for w in want if w not in added]
            paths = FleetPaths(Path(args.dir))
            if added:
                names = ", ".join(w.cn for w in added)
                print(f"revoked {names} in {paths.crl}: copy it to every host, restart the router")
            if again:
                print(f"already revoked: {', '.join(again)}")
        else:
            dst = export(Path(args.dir), Identity.parse(args.identity), Path(args.out))
            crl = ", crl.pem" if dst.crl.is_file() else ""
            print(f"wrote {dst.root}: ca.pem{crl}, certs/, keys/{args.identity}.key")
    except (ValueError, OSError) as exc:  # TrustError is a ValueError
        kind = "untrusted" if isinstance(exc, TrustError) else "error"
        print(f"fleet: {kind}: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
