"""The registry of peer kinds (sim/kinds/) and of truth models (sim/truths.py): every shipped
scenario's peers come from it; a kind registered from outside runs through ``run --sim``, real
processes, ``--record`` and ``replay``; seed 003's PDA peers built from the one scenario loader
compute what the seed's own peer builder computes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from sensornet.sim import kinds
from sensornet.sim.run.peers import make_parts
from sensornet.sim.run.twin import run_twin
from sensornet.sim.scenario import ScenarioError, builtin_scenarios, load_scenario
from sensornet.sim.studies.seed003 import network as seed003_net
from sensornet.sim.truths import truth_model

ROOT = Path(__file__).resolve().parents[1]
TOY = "toy=kind_plugin:TOY"


@pytest.fixture
def toy(monkeypatch):
    """The test plug-in kind, registered through the plug-in variable as processes see it."""
    monkeypatch.setenv(kinds.PLUGINS_ENV, TOY)
    monkeypatch.syspath_prepend(str(ROOT / "tests"))
    try:
        yield kinds.kind("toy")
    finally:
        kinds.unregister("toy")


def test_every_shipped_scenario_builds_its_peers_from_the_registry():
    seen = set()
    for name in builtin_scenarios():
        scn = load_scenario(name)
        k = kinds.kind_of(scn)
        est, fuser = make_parts(scn, scn.sensor_names[0])
        assert k.name == scn.network.filter and hasattr(est, "step") and hasattr(fuser, "fuse")
        seen.add(k.name)
    assert seen == {"gmphd", "imm-pf", "et-gmphd", "pda", "flooding"}
    assert set(kinds.names()) >= seen | {"imm-ekf"}


def test_unknown_kind_and_rule_are_one_line_errors():
    with pytest.raises(ScenarioError) as e:
        load_scenario("seed000", {"network.filter": "gmphdd"})
    assert "expected one of" in str(e.value) and "'gmphd'" in str(e.value)
    assert "\n" not in str(e.value)
    with pytest.raises(ScenarioError, match="'ratio', which 'gmphd' peers do not take"):
        load_scenario("seed000", {"fusion.rule": "ratio"})
    with pytest.raises(ScenarioError, match="'hybrid', which 'imm-pf' peers do not take"):
        load_scenario("seed001", {"fusion.rule": "hybrid"})
    with pytest.raises(KeyError, match="unknown peer kind 'nope'"):
        kinds.kind("nope")
    with pytest.raises(KeyError, match="unknown truth model"):
        truth_model("nope")


def test_bad_plugin_entry_is_a_clear_error(monkeypatch):
    monkeypatch.setenv(kinds.PLUGINS_ENV, "toy-without-target")
    with pytest.raises(ValueError, match="is not 'name=module:attribute'"):
        kinds.names()


@pytest.mark.parametrize("mode", ["meas", "ci"])
def test_seed003_from_the_scenario_loader_is_the_seeds_own_peers(mode):
    """`sensornet run seed003` now builds its PDA peers from the one loader: the twin's tracks
    equal those of sim/studies/seed003/network.py's own builder, scan for scan, bit for bit."""
    scn = load_scenario("seed003", {"pda.mode": mode, "scenario.num_scans": 40})
    assert scn.network.filter == "pda" and scn.truth == "seed003"
    ours = run_twin(scn, 2)
    ref = seed003_net.twin(seed003_net.load({"scenario.num_scans": 40}), mode, 2)
    for n in scn.sensor_names:
        assert sorted(ours.tracks[n]) == sorted(ref.tracks[n]) == list(range(1, 41))
        for k, x in ref.tracks[n].items():
            np.testing.assert_array_equal(ours.tracks[n][k], x)


def test_a_registered_kind_runs_in_the_twin(toy):
    scn = load_scenario("seed000", {"network.filter": "toy", "fusion.rule": "aa",
                                    "scenario.num_scans": 20})
    res = run_twin(scn, 0)
    for n in scn.sensor_names:
        s = res.summary(n)
        assert s["scans"] == 20 and np.isfinite(s["mean_ospa_fused"])
        assert s["mean_ospa_fused"] < scn.metrics.ospa_cutoff  # it finds targets, not nothing
    with pytest.raises(ScenarioError, match="which 'toy' peers do not take"):
        load_scenario("seed000", {"network.filter": "toy"})  # the default rule is hybrid


def _sensornet(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")]),
           kinds.PLUGINS_ENV: TOY, "RERUN_ANALYTICS": "0"}
    return subprocess.run([sys.executable, "-m", "sensornet", *args], capture_output=True,
                          text=True, timeout=timeout, env=env, cwd=ROOT)


SETS = ["--set", "network.filter=toy", "--set", "fusion.rule=aa",
        "--set", "scenario.num_scans=15", "--set", "network.deadline=0.9"]


@pytest.mark.network
def test_a_registered_kind_runs_as_processes_and_replays(tmp_path):
    """One module and one registry entry: `run` (world + 3 peer processes over Zenoh on
    127.0.0.1), `run --sim`, and `--record` + `replay` reproducing each peer's fused tracks."""
    out = tmp_path / "run"
    with ThreadPoolExecutor(max_workers=1) as pool:  # the twin (one process) beside the run
        twin = pool.submit(_sensornet, "run", "seed000", "--sim", *SETS)
        p = _sensornet("run", "seed000", *SETS, "--record", "--no-rerun", "--out", str(out))
        sim = twin.result()
    assert sim.returncode == 0, sim.stderr
    assert "twin run" in sim.stdout and "| s3 | 15 |" in sim.stdout
    assert p.returncode == 0, p.stderr[-2000:]
    for n in ("s1", "s2", "s3"):
        s = json.loads((out / f"peer-{n}.json").read_text())
        assert s["scans"] == 15 and s["stats"]["fusions"] > 0, s
    r = _sensornet("replay", str(out))
    assert r.returncode == 0, r.stderr
    assert r.stdout.count("| yes |") == 3, r.stdout


def test_readme_kind_example_runs():
    """The manual's two code blocks (the estimator, then its kind; README links to them)
    register and run as they are."""
    import re

    from sensornet.peers.contracts import LocalOutput
    from sensornet.peers.fusers import AaFuser
    from sensornet.sim.kinds import PeerKind
    from sensornet.tracking.mixture import GaussianMixture
    from sensornet.tracking.reduction import Reducer

    text = (ROOT / "docs" / "usage.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    est = next(b for b in blocks if "class CountingEstimator" in b)
    kind = next(b for b in blocks if "COUNTING = PeerKind" in b)
    ns = {"np": np, "GaussianMixture": GaussianMixture, "LocalOutput": LocalOutput,
          "PeerKind": PeerKind, "AaFuser": AaFuser, "Reducer": Reducer}
    exec(est + kind, ns)  # noqa: S102 (the README's own text)
    kinds.register(ns["COUNTING"])
    try:
        scn = load_scenario("seed000", {"network.filter": "counting", "fusion.rule": "aa",
                                        "scenario.num_scans": 5})
        res = run_twin(scn, 0)
        assert all(res.summary(n)["scans"] == 5 for n in scn.sensor_names)
    finally:
        kinds.unregister("counting")
