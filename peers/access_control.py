"""The network's Zenoh access-control policy: who may put and declare what (default deny).

Subjects are certificate common names (the member names of :mod:`peers.member_keys`); every
member loads the same policy (:meth:`peers.security.Security.apply`), so each refuses what
another member may not send, whatever that member's own process does.
"""

from __future__ import annotations

from collections.abc import Sequence

from sensornet.protocol.keys import ROUTER_PREFIX, WORLD, Keys, check_name

__all__ = ["OBSERVER", "OBSERVER_PREFIX", "ROUTER_PREFIX", "acl_rules"]

OBSERVER_PREFIX = "view"
"""Members named ``view*`` are read-only observers (a live view, ``sensornet view --secure``):
they may subscribe to what the view draws and put nothing."""
OBSERVER = "view"
"""The observer member ``sensornet keys`` and ``run --secure`` make (the run's view is it)."""


def acl_rules(network: str, peers: Sequence[str], world: str = WORLD,
              routers: Sequence[str] = (), observers: Sequence[str] = ()) -> dict:
    """The network's Zenoh ``access_control`` section (default deny).

    Zenoh checks a put or a declaration where it arrives (ingress, against the sender's
    certificate name) and where it leaves (egress, against the *receiver's*): every member
    loads this same policy, so each refuses what another member may not send, whatever that
    member's own process does. Subjects are certificate common names (reliable in peer mode;
    user names are not). Per member:

    - peer ``p``: puts ``estimate/p``, ``tracks/p`` and ``telemetry/p``; liveliness tokens
      ``alive/p`` and ``ready/p``; subscribes to its own ``scan/p``, ``truth``, ``ctl`` and
      ``estimate/*`` (what it fuses), to liveliness ``alive/*``;
    - the world: puts ``scan/*``, ``truth``, ``ctl``; token ``alive/<world>``; liveliness
      subscriptions on ``alive/*`` and ``ready/*``; subscribes to ``scan/*`` (its own tools);
    - recovery (``--recover``, Zenoh's advanced publisher/subscriber, routed runs): a
      publisher of ``K`` also puts heartbeats on ``K/@adv/**`` and answers queries there from
      its cache; a subscriber subscribes and queries there. The same owners as ``K``: peer
      ``p`` on ``estimate/p/@adv/**``, the world on ``scan/*/@adv/**``; peer ``p`` asks on
      ``scan/p/@adv/**`` and ``estimate/*/@adv/**``;
    - a router (``routers``): relays anything on the network's keys. A member behind a router
      sees every message as coming from the router's certificate, so the router is where the
      per-member rules are enforced (at its ingress, by the client's certificate name);
    - an observer (``observers``, read-only): subscribes to the scans, truth, control,
      estimates, tracks and telemetry of every member, and to liveliness ``alive/*`` (a run's
      view waits for the peers); puts, declares and queries nothing else, so every member
      refuses anything it sends but its subscriptions.
    """
    k = Keys(network)
    rules = [*_world_rules(k, world), *_shared_rules(k)]
    subjects = [{"id": f"m-{world}", "cert_common_names": [world]}]
    policies = [_policy(world, [r["id"] for r in rules])]
    for p in peers:
        check_name(p, "peer name")
        mine = _peer_rules(k, p)
        rules += mine
        subjects.append({"id": f"m-{p}", "cert_common_names": [p]})
        policies.append(_policy(p, [r["id"] for r in mine] + [_REPLIES, _SEND]))
    if routers:
        rules.append(_rule("relay", _RELAYED, _everything(k), flows=("ingress", "egress")))
        for r in routers:
            check_name(r, "router name")
            subjects.append({"id": f"m-{r}", "cert_common_names": [r]})
        policies.append({"rules": ["relay"], "subjects": [f"m-{r}" for r in routers]})
    if observers:
        rules.append(_rule("observe", ["declare_subscriber"],
                           [k.scan("*"), k.scans("*"), k.truth(), k.ctl(), k.estimate("*"),
                            k.tracks("*"), k.telemetry("*")]))
        # who is up: a run's view waits for the peers' tokens before the truth (sensornet.view)
        rules.append(_rule("observe-live", ["declare_liveliness_subscriber", "liveliness_query"],
                           [k.alive("*")]))
        for o in observers:
            check_name(o, "observer name")
            subjects.append({"id": f"m-{o}", "cert_common_names": [o]})
        policies.append({"rules": ["observe", "observe-live", _REPLIES, _SEND],
                         "subjects": [f"m-{o}" for o in observers]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}


_REPLIES, _SEND = "replies", "send"
"""The rules every member's policy ends with (:func:`_shared_rules`)."""
_RELAYED = ["put", "delete", "liveliness_token", "declare_subscriber",
            "declare_liveliness_subscriber", "liveliness_query", "reply", "query",
            "declare_queryable"]
"""Every message kind: what a member may send out (egress) and a router relay."""


def _rule(rid: str, messages: list[str], key_exprs: list[str],
          flows: tuple[str, ...] = ("ingress",)) -> dict:
    return {"id": rid, "permission": "allow", "flows": list(flows), "messages": list(messages),
            "key_exprs": list(key_exprs)}


def _adv(key: str) -> str:
    """The advanced publisher's keys of ``key`` (heartbeats, cache queries)."""
    return f"{key}/@adv/**"


def _everything(k: Keys) -> list[str]:
    """Every key of the network: ``**`` does not match a chunk that starts with "@", so the
    advanced pub/sub keys are spelled out."""
    return [f"{k.base}/**", f"{k.base}/*/*/@adv/**"]


def _policy(member: str, rule_ids: list[str]) -> dict:
    return {"rules": rule_ids, "subjects": [f"m-{member}"]}


def _world_rules(k: Keys, world: str) -> list[dict]:
    """The world's: puts scans, truth and ctl; its token; hears who is alive and ready."""
    return [
        _rule(f"{world}-put", ["put"], [k.scan("*"), k.truth(), k.ctl()]),
        _rule(f"{world}-token", ["liveliness_token"], [k.alive(world)]),
        _rule(f"{world}-hear", ["declare_liveliness_subscriber", "liveliness_query"],
              [k.alive("*"), k.ready("*")]),
        # the world's own tools (the launcher's process-fault injector) follow the scans
        _rule(f"{world}-watch", ["declare_subscriber"], [k.scan("*")]),
        # recovering scan publishers: heartbeats, and a cache that answers queries
        _rule(f"{world}-recover", ["put", "declare_queryable"], [_adv(k.scan("*"))]),
    ]


def _shared_rules(k: Keys) -> list[dict]:
    """Every member's: replies in, anything out."""
    return [
        # liveliness replies (who is alive) and replies from a publisher's cache, on every
        # member's ingress (a reply answers a query its receiver made)
        _rule(_REPLIES, ["reply"], _everything(k)),
        # egress is checked against the receiving member: a member sends what it may send
        # (every receiver checks the sender on its ingress)
        _rule(_SEND, _RELAYED, _everything(k), flows=("egress",)),
    ]


def _peer_rules(k: Keys, p: str) -> list[dict]:
    """Peer ``p``'s: puts its estimates, tracks and telemetry, its tokens, hears what it
    fuses."""
    return [
        _rule(f"{p}-put", ["put"], [k.estimate(p), k.tracks(p), k.telemetry(p)]),
        _rule(f"{p}-token", ["liveliness_token"], [k.alive(p), k.ready(p)]),
        _rule(f"{p}-hear", ["declare_subscriber"],
              [k.scan(p), k.truth(), k.ctl(), k.estimate("*")]),
        _rule(f"{p}-live", ["declare_liveliness_subscriber", "liveliness_query"],
              [k.alive("*")]),
        _rule(f"{p}-recover", ["put", "declare_queryable"], [_adv(k.estimate(p))]),
        _rule(f"{p}-ask", ["declare_subscriber", "query"],
              [_adv(k.scan(p)), _adv(k.estimate("*"))]),
    ]
