"""Every flag is honoured or refused (issue 16), without starting a network.

Each refusal is checked through a real ``sensornet`` process: exit code 2, exactly one line on
stderr naming the problem, no traceback, and no run folder left behind.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from sensornet.sim.scenario import load_scenario, scenario_text

from sensornet.cli import COMMANDS, budgets, build_parser, common, main
from sensornet.cli.commands.peer import _prepare_peer

ROOT = Path(__file__).resolve().parents[1]

# the CLI is exercised as a user runs it: as a subprocess, so the tests that start one are marked
# network (the fast '-m "not network"' run, which starts no process, leaves them to the full
# suite); the ones below that call the CLI in this process are not, so they run beside them


def _cli(*args: str, cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RERUN_ANALYTICS": "0"}
    return subprocess.run([sys.executable, "-m", "sensornet", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd, env=env)


def _cli_each(*commands: list[str], cwd: Path) -> list[subprocess.CompletedProcess]:
    """Several ``_cli`` runs at once, each its own process in ``cwd``: their results in order
    (their interpreter start-ups, one after another, were most of these tests' time)."""
    with ThreadPoolExecutor(max_workers=4) as pool:
        return list(pool.map(lambda argv: _cli(*argv, cwd=cwd, timeout=240), commands))


def _refused(proc: subprocess.CompletedProcess, *needles: str) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def _no_run_folders(cwd: Path) -> None:
    runs = cwd / "runs"
    assert not runs.exists() or not any(runs.iterdir()), list(runs.iterdir())


# --- "Tracebacks instead of one-line errors" and "zero means not set" ----------------------

BAD_FLAGS = [
    (["peer", "s1", "--network", "x", "--rounds", "-1"], "--rounds"),
    (["peer", "s1", "--network", "x", "--rounds", "0"], "--rounds"),
    (["peer", "s1", "--network", "a/b*"], "--network"),
    (["world", "--network", "a b"], "--network"),
    (["run", "--sim", "--run", "-1"], "--run"),
    (["run", "--speed", "-1"], "--speed"),
    (["run", "--speed", "0"], "--speed"),
    (["demo", "--speed", "nan"], "--speed"),
    (["run", "--timeout", "-5"], "--timeout"),
    (["run", "--viewer", "nonsense"], "--viewer"),
    (["demo", "--viewer", "rerun+http://127.0.0.1:9876"], "--viewer"),
    (["peer", "s1", "--network", "x", "--viewer", "nonsense"], "--viewer"),
    (["world", "--network", "x", "--viewer", "nonsense"], "--viewer"),
    (["peer", "s1", "--network", "x", "--idle-timeout", "-1"], "--idle-timeout"),
    (["peer", "s1", "--network", "x", "--lease-ms", "-5"], "--lease-ms"),
    (["run", "--lease-ms", "0"], "--lease-ms"),
    (["world", "--network", "x", "--wait", "-1"], "--wait"),
    (["world", "--network", "x", "--progress-every", "0"], "--progress-every"),
    (["experiment", "--runs", "0"], "--runs"),
    (["experiment", "--jobs", "0"], "--jobs"),
    (["sweep", "--param", "a", "--values", "1", "--runs", "-2"], "--runs"),
    (["run", "--listen", "7447"], "--listen"),
    (["demo", "--connect", "nowhere"], "--connect"),
    (["run", "--config", "no-such-file.json5"], "--config"),
    (["run", "--run-id", "a/b"], "--run-id"),
    (["run", "--max-points", "0"], "--max-points"),
    (["experiment", "--max-memory-gb", "-1"], "--max-memory-gb"),
]


SIM_REFUSED = [(["run", "--sim", f], f.split()[0]) for f in (
    "--listen=tcp/127.0.0.1:7447", "--connect=tcp/127.0.0.1:7447", "--run-id=x",
    "--viewer=spawn", "--lease-ms=100")]


@pytest.fixture(scope="module")
def refusals(request, tmp_path_factory) -> dict[tuple[str, ...], tuple[
        subprocess.CompletedProcess, Path]]:
    """Each command line of the two parametrized refusal tests below that this session
    selected, run once as its own ``sensornet`` process in its own empty folder: (process,
    folder) by argv. They run four at a time (one after another, their interpreter start-ups
    were most of this module's time); each test then checks its own process as before."""
    wanted = sorted({tuple(item.callspec.params["argv"]) for item in request.session.items
                     if item.module is request.module and hasattr(item, "callspec")
                     and "argv" in item.callspec.params})

    def one(argv: tuple[str, ...]) -> tuple[subprocess.CompletedProcess, Path]:
        cwd = tmp_path_factory.mktemp("refused")
        return _cli(*argv, cwd=cwd, timeout=240), cwd

    with ThreadPoolExecutor(max_workers=4) as pool:
        return dict(zip(wanted, pool.map(one, wanted), strict=True))


@pytest.mark.network
@pytest.mark.parametrize("argv, flag", BAD_FLAGS, ids=[" ".join(a) for a, _ in BAD_FLAGS])
def test_bad_flag_value_is_one_line_and_exit_2(refusals, argv, flag):
    proc, cwd = refusals[tuple(argv)]
    line = _refused(proc, flag)
    assert line.startswith("sensornet")
    _no_run_folders(cwd)


@pytest.mark.network
@pytest.mark.parametrize("argv, flag", SIM_REFUSED)
def test_process_flags_with_sim_are_refused(refusals, argv, flag):
    _refused(refusals[tuple(argv)][0], flag.split("=")[0], "--sim")


@pytest.mark.network
def test_listen_on_a_port_in_use_is_refused_before_anything_starts(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        for proc in _cli_each(*([command, "--listen", f"tcp/127.0.0.1:{port}"]
                                for command in ("run", "demo")), cwd=tmp_path):
            _refused(proc, f"--listen tcp/127.0.0.1:{port}")
    _no_run_folders(tmp_path)


@pytest.mark.network
def test_broken_pipe_is_quiet(tmp_path):
    """``sensornet experiment | head``: the reader leaves; no traceback."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for argv in (["scenario", "show", "seed000"],
                 ["experiment", "--runs", "1", "--quiet", "--jobs", "1", "--set",
                  "scenario.num_scans=5", "--out", str(tmp_path / "out")]):
        proc = subprocess.Popen([sys.executable, "-m", "sensornet", *argv], cwd=tmp_path,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        proc.stdout.close()  # as `head` does once it has its lines
        err = proc.stderr.read().decode()
        proc.stderr.close()
        assert proc.wait(timeout=120) == 141, err
        assert err == "", err


# --- budgets --------------------------------------------------------------------------------


def _many_targets(n: int) -> str:
    text = scenario_text("seed000")
    extra = "".join(
        f"\n[[targets]]\nbirth_scan = 1\ndeath_scan = 5\nstart = [{i % 100 * 10.0 - 500.0}, 0.0]"
        f"\nend = [0.0, {i % 50 * 10.0}]\n" for i in range(n))
    return text.replace("# Sensors. kind", extra + "\n# Sensors. kind", 1)


def _many_sensors(n: int) -> str:
    text = scenario_text("seed000")
    extra = "".join(
        f'\n[[sensors]]\nname = "x{i}"\nkind = "linear"\nposition = [0.0, {float(i)}]\n'
        f"sigma_r = 20.0\ndetection_probability = 0.9\nclutter_rate = 1\n" for i in range(n))
    return text.replace("# A radar instead", extra + "\n# A radar instead", 1)


@pytest.mark.network
def test_too_many_points_per_scan_is_refused(tmp_path):
    clutter = "sensors.s1.clutter_rate=1000000"
    experiment, sim, processes = _cli_each(
        ["experiment", "--set", clutter, "--runs", "1"], ["run", "--sim", "--set", clutter],
        ["run", "--set", "sensors.s1.clutter_rate=30000", "--max-points", "100000"],
        cwd=tmp_path)
    _refused(experiment, "s1", "points per scan", "--max-points")
    _refused(sim, "--max-points")
    # over processes a scan message carries at most so many points, whatever the budget
    _refused(processes, "s1", "scan message", "experiment")
    _no_run_folders(tmp_path)


@pytest.mark.network
def test_too_many_targets_is_refused(tmp_path):
    crowd, crowds = tmp_path / "crowd.toml", tmp_path / "crowds.toml"
    crowd.write_text(_many_targets(600))
    crowds.write_text(_many_targets(2100))
    experiment, processes = _cli_each(
        ["experiment", str(crowd), "--runs", "1"],
        ["run", str(crowds), "--max-targets", "5000", "--max-points", "50000"], cwd=tmp_path)
    _refused(experiment, "targets", "--max-targets")
    _refused(processes, "truth message")
    _no_run_folders(tmp_path)


@pytest.mark.network
def test_too_many_peers_is_refused(tmp_path):
    path = tmp_path / "crowd.toml"
    path.write_text(_many_sensors(40))
    peers, memory, packed = _cli_each(
        ["run", str(path), "--per-process", "1"],
        ["run", str(path), "--max-peers", "50", "--max-memory-gb", "0.5", "--per-process", "1"],
        ["run", str(path), "--max-memory-gb", "0.5"], cwd=tmp_path)
    _refused(peers, "43 peer processes", "--max-peers")
    _refused(memory, "memory", "--max-memory-gb")
    # packed in hosts (the default above sim.run.packing.PACK_ABOVE peers): a few processes, so
    # the peer budget passes and the next check (memory, squeezed here) is the one that speaks
    _refused(packed, "memory")
    _no_run_folders(tmp_path)


def test_memory_estimate_grows_with_the_work():
    scn = load_scenario("seed000")
    base = budgets.memory_estimate_gb(scn)
    assert 0.1 < base < 1.0
    assert budgets.memory_estimate_gb(scn, workers=4) > 3 * base
    big = load_scenario("seed000", {"sensors.s1.clutter_rate": 4000})
    assert budgets.memory_estimate_gb(big) > base
    assert budgets.targets_at_once(scn) == 4  # 1-100, 20-60, 40-80, 40-80: four at scans 40-60
    assert budgets.points_per_scan(scn)["s1"] == pytest.approx(10 + 4 * 0.99)


# --- run seed000 and the demo agree -----------------------------------------------------


def test_demo_is_run_seed000_with_a_viewer():
    parser = build_parser()
    demo, run = vars(parser.parse_args(["demo"])), vars(parser.parse_args(["run", "seed000"]))
    assert demo.pop("viewer") == "spawn" and run.pop("viewer") is None
    for d in (demo, run):
        # --sim and its --twin-workers are run's alone (the demo is processes and a viewer)
        d.pop("command"), d.pop("sim", None), d.pop("twin_workers", None), d.pop("scenario", None)
    assert demo == run
    assert COMMANDS["demo"].split(":")[0] == COMMANDS["run"].split(":")[0]  # one module
    assert load_scenario("seed000").birth.model == "truth"  # chosen in the scenario file


def test_run_seed000_fused_beats_every_local(capsys):
    assert main(["run", "--sim", "seed000"]) == 0
    rows = [r.split("|") for r in capsys.readouterr().out.splitlines() if r.startswith("| s")]
    assert len(rows) == 3
    for r in rows:
        local, fused = float(r[3]), float(r[4])
        assert fused < local, r


# --- nothing scored, run folders -------------------------------------------------------------


def test_run_that_scored_nothing_exits_nonzero(tmp_path, monkeypatch, capsys):
    import sensornet.sim.run.launcher as launcher

    class Handle:
        logs = {n: tmp_path / f"{n}.log" for n in ("world", "s1", "s2", "s3")}
        procs: dict = {}
        timed_out = False  # as a RunHandle whose run ended by itself

    summary = {"scans": 0, "mean_ospa_local": None, "mean_ospa_fused": None,
               "messages_sent": 0, "messages_received": 0, "bytes_sent": 0,
               "bytes_received": 0, "rejected_total": 100, "rejected": {"too-many": 100},
               "mean_estimate_age": None, "latency_ms_median": None, "latency_ms_p99": None}
    monkeypatch.setattr(launcher, "start_run", lambda *a, **k: Handle())
    monkeypatch.setattr(launcher, "wait_run",
                        lambda *a, **k: {"world": 0, "s1": 0, "s2": 0, "s3": 0})
    monkeypatch.setattr(launcher, "read_summaries",
                        lambda out, names: {n: dict(summary) for n in names})
    monkeypatch.setattr(launcher, "merge_recordings", lambda out: None)
    assert main(["run", "--out", str(tmp_path / "run"), "--viewer", "none"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "s1 scored no scan" in err[0] and "too-many" in err[0], err


def test_run_folders_are_unique_and_failed_ones_removed(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    a, b = common._run_folder(None, "run"), common._run_folder(None, "run")
    assert a != b and a.is_dir() and b.is_dir()  # the same second: distinct folders
    common._CREATED.clear()

    import sensornet.sim.studies.base

    def fail(*args, **kwargs):
        raise common.UserError("stop here")

    monkeypatch.setattr(sensornet.sim.studies.base, "run_study", fail)
    before = set((tmp_path / "runs").iterdir())
    assert main(["experiment", "--runs", "1", "--quiet"]) == 2
    assert set((tmp_path / "runs").iterdir()) == before  # the empty folder went again
    assert main(["experiment", "--runs", "1", "--quiet", "--out", "mine"]) == 2
    assert not (tmp_path / "mine").exists()


def test_viewer_probe(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        url = f"rerun+http://127.0.0.1:{s.getsockname()[1]}/proxy"
        assert common.viewer_reachable(url)
    assert not common.viewer_reachable(url, timeout=0.5)


# --- files ------------------------------------------------------------------------------


def test_scenario_files_cite_only_the_projects_docs():
    for name in ("seed000", "seed001"):
        text = scenario_text(name)
        assert "ALGORITHMS.md" not in text
        for cited in ("docs/algorithms.md", "docs/seed001.md"):
            if cited in text:
                assert (ROOT / cited).is_file()


def test_a_peer_started_by_hand_takes_its_sensors_colour():
    """Four terminals: each peer gets the colour the world's legend and plots give it."""
    args = build_parser().parse_args(["peer", "s2", "--network", "lab"])
    assert args.color is None
    _prepare_peer(args, load_scenario("seed000"))
    assert args.color == 1
