"""The live view joins a secure network (issue 38): ``sensornet keys`` makes a read-only
observer member ``view``; the access control lets it subscribe to what the view draws and put
nothing; ``sensornet run --secure`` starts its view as that observer and records the peers'
tracks and telemetry. Without processes: the policy and the command's checks; with processes
(network): a secure run's recording, and the observer's forgeries refused by every peer."""

from __future__ import annotations

import json
import subprocess
import threading
import time

import numpy as np
import pytest
from sensornet.peers.access_control import OBSERVER, acl_rules
from sensornet.peers.security import Security, make_keys
from sensornet.peers.session import open_session
from sensornet.protocol.codec import decode, encode
from sensornet.protocol.envelope import inner
from sensornet.protocol.keys import Keys
from sensornet.protocol.messages import Control, Estimate, Tracks
from sensornet.sim.run.launcher import _view_command
from sensornet.sim.run.router import router_security
from sensornet.tracking.mixture import GaussianMixture

from sensornet.cli import main
from sensornet.cli.parser import build_parser
from tests.processes import end_once_view_drew, env, rerun_exe, sensornet, wait_for

NETWORK = "viewsec"
PEERS = ("s1", "s2", "s3")


def _policy(acl: dict, member: str) -> set[str]:
    """The rule ids of ``member``'s policies."""
    return {r for p in acl["policies"] for r in p["rules"] if f"m-{member}" in p["subjects"]}


def test_the_observer_may_subscribe_and_put_nothing():
    acl = acl_rules(NETWORK, PEERS, observers=[OBSERVER])
    rules = {r["id"]: r for r in acl["rules"]}
    mine = _policy(acl, OBSERVER)
    ingress = [rules[r] for r in mine if "ingress" in rules[r]["flows"]]
    # what others accept from it: its subscriptions, to liveliness too (a run's view waits
    # for the peers' tokens), and replies to queries
    assert {m for r in ingress for m in r["messages"]} == {
        "declare_subscriber", "declare_liveliness_subscriber", "liveliness_query", "reply"}
    assert rules["observe-live"]["key_exprs"] == [Keys(NETWORK).alive("*")]
    k = Keys(NETWORK)
    assert set(rules["observe"]["key_exprs"]) == {
        k.scan("*"), k.scans("*"), k.truth(), k.ctl(), k.estimate("*"), k.tracks("*"),
        k.telemetry("*")}
    for p in PEERS:  # a peer may put its telemetry: the view hears it in secure mode
        assert k.telemetry(p) in rules[f"{p}-put"]["key_exprs"]
    assert "observe" not in acl_rules(NETWORK, PEERS)["rules"]  # no observer, no rule


def test_keys_make_the_observer_and_the_view_joins_only_as_one(tmp_path, capsys):
    folder = tmp_path / "k"
    assert main(["keys", NETWORK, "--scenario", "seed000", "--out", str(folder)]) == 0
    assert "view" in capsys.readouterr().out
    sec = Security.load(folder, OBSERVER, NETWORK, PEERS)
    assert sec.observers == (OBSERVER,)  # from the roster: every member loads the rule
    assert Security.load(folder, "s1", NETWORK, PEERS).observers == (OBSERVER,)
    make_keys(NETWORK, ["router"], folder)
    router = router_security(folder, "router")  # its peers from the roster: not the view
    assert OBSERVER not in router.peers and router.observers == (OBSERVER,)
    ids = [s["id"] for s in acl_rules(NETWORK, router.peers, observers=router.observers)[
        "subjects"]]
    assert len(ids) == len(set(ids))  # Zenoh refuses a policy with a repeated subject
    base = ["view", NETWORK, "--connect", "tls/127.0.0.1:1", "--out", str(tmp_path / "v.rrd")]
    for extra, said in ((["--secure", str(folder), "--as", "s1"], "read-only observer"),
                        (["--as", "view"], "--as needs --secure"),
                        (["--secure", str(tmp_path / "none")], "ca.pem")):
        assert main([*base, *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], err


def test_a_routed_runs_view_connects_to_the_router_once_and_gets_no_peer_flags(tmp_path):
    ep = "tls/127.0.0.1:7000"
    cfg = tmp_path / "c.json5"
    cfg.write_text("{}")
    common = ["--network", NETWORK, "--config", str(cfg), "--secure", "k"]
    cmd = _view_command(NETWORK, ep, ["--connect", ep, "--recover"], "seed000", [], "r",
                        common, tmp_path, True, None)
    assert "--recover" not in cmd and cmd.count("--connect") == 1
    assert cmd[cmd.index("--secure") + 1] == "k" and cmd[cmd.index("--config") + 1] == str(cfg)
    args = build_parser().parse_args(cmd[cmd.index("view"):])  # every flag is the view's
    assert args.connect == [ep] and args.secure == "k" and args.until_end


def _forge_as_observer(keys, endpoint: str, report: dict) -> None:
    """As the observer: follow the run's scans (allowed), then, for 5 scans, put forged
    estimates, tracks and an "end", and declare a peer's liveliness token (all refused)."""
    k = Keys(NETWORK)
    session = open_session(connect=[endpoint], security=Security.load(
        keys, OBSERVER, NETWORK, PEERS))
    seen = {"k": 0, "first": None}
    started, done = threading.Event(), threading.Event()

    def on_scan(sample) -> None:
        seen["k"] = max(seen["k"], decode(inner(sample.payload.to_bytes())).k)
        seen["first"] = seen["first"] or seen["k"]
        started.set()
        if seen["k"] >= seen["first"] + 5:
            done.set()

    sub = session.declare_subscriber(k.scan("*"), on_scan)
    token = None
    try:
        report["heard"] = started.wait(150)
        empty = GaussianMixture(np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4, 4)))
        token = session.liveliness().declare_token(k.alive("s1"))
        while not done.wait(0.05):
            kk = seen["k"]
            session.put(k.estimate("s2"), encode(Estimate("s2", kk, empty,
                                                          send_time=time.time())))
            session.put(k.tracks("s1"), encode(Tracks("s1", kk, np.full((1, 4), 9e5))))
            session.put(k.ctl(), encode(Control("end", "forged", {})))
            report["sent"] = report.get("sent", 0) + 3
    finally:
        if token is not None:
            token.undeclare()
        sub.undeclare()
        session.close()


@pytest.mark.network
def test_a_secure_run_records_through_the_view_and_the_observer_cannot_speak(tmp_path):
    keys = tmp_path / "keys"
    assert main(["keys", NETWORK, "--scenario", "seed000", "--out", str(keys)]) == 0
    out = tmp_path / "run"
    report: dict = {}
    # 3000 scans at 2 scans/s: the run ends once the view says it drew every peer (its
    # world's SIGTERM); a 40-scan run took 8 s, and the view, which imports for seconds
    # longer than the peers on a busy machine, could link after its end
    with sensornet(["run", "seed000", "--secure", str(keys), "--viewer", "none", "--out",
                    str(out), "--set", "scenario.num_scans=3000", "--speed", "2"],
                   tmp_path) as run:
        cmds = out / "commands.json"
        log = out / "logs" / "world.log"
        wait_for(lambda: log.is_file() and "waiting" in log.read_text(), 120, "the world")
        commands = json.loads(cmds.read_text())
        world = commands["world"][commands["world"].index("--listen") + 1]
        _forge_as_observer(keys, world, report)
        end_once_view_drew(run, out, PEERS)
        _, stderr = run.proc.communicate(timeout=300)
    assert run.proc.returncode == 0, stderr[-2000:]
    assert report["heard"] and report["sent"] >= 3, report
    view = commands["view"]
    assert view[view.index("--secure") + 1] == str(keys.resolve())
    assert sorted(p.name for p in (out / "rerun").glob("*.rrd")) == ["view.rrd"]
    assert "messages drawn" in (out / "logs" / "view.log").read_text()
    text = subprocess.run([rerun_exe(), "rrd", "print", str(out / "recording.rrd")],
                          capture_output=True, text=True, timeout=120, env=env()).stdout
    for entity in ["/world/truth", "/world/scans/s1"] + [
            f"/peers/{p}/{what}" for p in PEERS for what in ("tracks", "fused/ellipses")] + [
            f"/metrics/latency_ms/{p}" for p in PEERS]:  # telemetry: through the ACL
        assert entity in text, entity
    refused = {}
    last = json.loads((out / f"peer-{PEERS[0]}.json").read_text())["last_k"]
    for name in PEERS:
        s = json.loads((out / f"peer-{name}.json").read_text())
        assert s["scans"] == s["last_k"] == last and s["stop_reason"] == "end of run", name
        assert s["rejected_total"] == 0, (name, s["rejected"])  # nothing reached a core
        assert s["ctl_end_while_world_alive"] <= 1, name  # only the world's own "end"
        # each other's estimates fused to the end (the last scan's may go at its deadline:
        # the world's end comes right after its scans once the world is stopped)
        fused = s["stats"]["last_fused_from"]
        assert set(fused) == set(PEERS) - {name}, name
        assert all(k >= last - 1 for k in fused.values()), (name, fused, last)
        refused[name] = s["refused_by_transport"]
    assert any(refused.values()), refused  # the transport refused the observer's forgeries
