"""The network's Zenoh access-control policy: who may put and declare what (default deny).

Subjects are certificate common names (the member names of :mod:`peers.member_keys`); every
member loads the same policy (:meth:`peers.security.Security.apply`), so each refuses what
another member may not send, whatever that member's own process does.
"""

from __future__ import annotations

from collections.abc import Sequence

from sensornet.protocol.keys import ROUTER_PREFIX, WORLD, Keys, check_name

__all__ = ["ROUTER_PREFIX", "acl_rules"]


def acl_rules(network: str, peers: Sequence[str], world: str = WORLD,
              routers: Sequence[str] = ()) -> dict:
    """The network's Zenoh ``access_control`` section (default deny).

    Zenoh checks a put or a declaration where it arrives (ingress, against the sender's
    certificate name) and where it leaves (egress, against the *receiver's*): every member
    loads this same policy, so each refuses what another member may not send, whatever that
    member's own process does. Subjects are certificate common names (reliable in peer mode;
    user names are not). Per member:

    - peer ``p``: puts ``estimate/p`` and ``tracks/p``; liveliness tokens ``alive/p`` and
      ``ready/p``; subscribes to its own ``scan/p``, ``truth``, ``ctl`` and ``estimate/*``
      (what it fuses), to liveliness ``alive/*``;
    - the world: puts ``scan/*``, ``truth``, ``ctl``; token ``alive/<world>``; liveliness
      subscriptions on ``alive/*`` and ``ready/*``; subscribes to ``scan/*`` (its own tools);
    - recovery (``--recover``, Zenoh's advanced publisher/subscriber, routed runs): a
      publisher of ``K`` also puts heartbeats on ``K/@adv/**`` and answers queries there from
      its cache; a subscriber subscribes and queries there. The same owners as ``K``: peer
      ``p`` on ``estimate/p/@adv/**``, the world on ``scan/*/@adv/**``; peer ``p`` asks on
      ``scan/p/@adv/**`` and ``estimate/*/@adv/**``;
    - a router (``routers``): relays anything on the network's keys. A member behind a router
      sees every message as coming from the router's certificate, so the router is where the
      per-member rules are enforced (at its ingress, by the client's certificate name).
    """
    k = Keys(network)
    everything = f"{k.base}/**"
    # ``**`` does not match a chunk that starts with "@": the advanced pub/sub keys, spelled out
    recovery = f"{k.base}/*/*/@adv/**"

    def adv(key: str) -> str:
        return f"{key}/@adv/**"

    def rule(rid: str, messages: list[str], key_exprs: list[str],
             flows: tuple[str, ...] = ("ingress",)) -> dict:
        return {"id": rid, "permission": "allow", "flows": list(flows), "messages": messages,
                "key_exprs": key_exprs}

    rules = [
        rule(f"{world}-put", ["put"], [k.scan("*"), k.truth(), k.ctl()]),
        rule(f"{world}-token", ["liveliness_token"], [k.alive(world)]),
        rule(f"{world}-hear", ["declare_liveliness_subscriber", "liveliness_query"],
             [k.alive("*"), k.ready("*")]),
        # the world's own tools (the launcher's process-fault injector) follow the scans
        rule(f"{world}-watch", ["declare_subscriber"], [k.scan("*")]),
        # recovering scan publishers: heartbeats, and a cache that answers queries
        rule(f"{world}-recover", ["put", "declare_queryable"], [adv(k.scan("*"))]),
        # liveliness replies (who is alive) and replies from a publisher's cache, on every
        # member's ingress (a reply answers a query its receiver made)
        rule("replies", ["reply"], [everything, recovery]),
        # egress is checked against the receiving member: a member sends what it may send
        # (every receiver checks the sender on its ingress)
        rule("send", ["put", "delete", "liveliness_token", "declare_subscriber",
                      "declare_liveliness_subscriber", "liveliness_query", "reply", "query",
                      "declare_queryable"],
             [everything, recovery], flows=("egress",)),
    ]
    subjects = [{"id": f"m-{world}", "cert_common_names": [world]}]
    policies = [{"rules": [f"{world}-put", f"{world}-token", f"{world}-hear",
                           f"{world}-watch", f"{world}-recover", "replies", "send"],
                 "subjects": [f"m-{world}"]}]
    for p in peers:
        check_name(p, "peer name")
        rules += [
            rule(f"{p}-put", ["put"], [k.estimate(p), k.tracks(p)]),
            rule(f"{p}-token", ["liveliness_token"], [k.alive(p), k.ready(p)]),
            rule(f"{p}-hear", ["declare_subscriber"],
                 [k.scan(p), k.truth(), k.ctl(), k.estimate("*")]),
            rule(f"{p}-live", ["declare_liveliness_subscriber", "liveliness_query"],
                 [k.alive("*")]),
            rule(f"{p}-recover", ["put", "declare_queryable"], [adv(k.estimate(p))]),
            rule(f"{p}-ask", ["declare_subscriber", "query"],
                 [adv(k.scan(p)), adv(k.estimate("*"))]),
        ]
        subjects.append({"id": f"m-{p}", "cert_common_names": [p]})
        policies.append({"rules": [f"{p}-put", f"{p}-token", f"{p}-hear", f"{p}-live",
                                   f"{p}-recover", f"{p}-ask", "replies", "send"],
                         "subjects": [f"m-{p}"]})
    if routers:
        rules.append(rule("relay", ["put", "delete", "liveliness_token", "declare_subscriber",
                                    "declare_liveliness_subscriber", "liveliness_query",
                                    "reply", "query", "declare_queryable"],
                          [everything, recovery], flows=("ingress", "egress")))
        for r in routers:
            check_name(r, "router name")
            subjects.append({"id": f"m-{r}", "cert_common_names": [r]})
        policies.append({"rules": ["relay"], "subjects": [f"m-{r}" for r in routers]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}
