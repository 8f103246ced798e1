"""The command line: user errors are one line with exit code 2; quick commands work."""

from __future__ import annotations

import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import pytest
from sensornet.sim.scenario import scenario_text

from sensornet.cli import main


def _cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sensornet", *args], capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.parametrize("edit, needle", [
    (lambda t: t.replace("merge_threshold = 5.0", "merge_treshold = 5.0"), "merge_treshold"),
    (lambda t: t.replace("sigma_r = 20.0", "sigma_r = -20.0", 1), "sigma_r"),
    (lambda t: t.replace("cov_diag = [100.0, 2500.0, 100.0, 2500.0]",
                         "cov = [[1.0, 2.0, 0.0, 0.0], [2.0, 1.0, 0.0, 0.0], "
                         "[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]"), "birth"),
])
@pytest.mark.network  # runs the CLI as a subprocess
def test_bad_scenario_file_is_one_line_exit_2(tmp_path, edit, needle):
    text = edit(scenario_text("seed000"))
    assert text != scenario_text("seed000"), "the edit did not apply"
    path = tmp_path / "bad.toml"
    path.write_text(text)
    commands = (["experiment", str(path), "--runs", "1", "--quiet", "--out",
                 str(tmp_path / "out")],
                ["run", str(path), "--sim"])
    with ThreadPoolExecutor(max_workers=2) as pool:  # two processes at once: mostly start-up
        procs = list(pool.map(lambda command: _cli(*command), commands))
    for proc in procs:
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and needle in lines[0], proc.stderr
        assert "Traceback" not in proc.stderr


def test_unknown_override_and_missing_file_are_user_errors(tmp_path, capsys):
    assert main(["run", "--sim", "--set", "network.topolgy=ring"]) == 2
    assert "network.topolgy" in capsys.readouterr().err
    assert main(["experiment", str(tmp_path / "nope.toml"), "--runs", "1", "--out",
                 str(tmp_path / "out")]) == 2
    assert main(["run", "--sim", "--fault", "kill:s1@3"]) == 2


@pytest.mark.parametrize("argv", [
    ["run", "--fault", "kill:s2@300"],                   # processes: 100 scans
    ["run", "--sim", "--fault", "kill:s2@300"],          # the twin
    ["demo", "--fault", "stop:s1@100"],                  # at the last scan
    ["run", "--set", "scenario.num_scans=20", "--fault", "kill:s1@5", "--fault",
     "restart:s3@20"],
])
def test_fault_at_or_after_the_last_scan_is_refused(argv, tmp_path, capsys):
    """A process fault the run never reaches was accepted and never fired: refused, one line
    naming the fault and the run's length, before any process or folder."""
    assert main([*argv, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    fault = next(a for a in reversed(argv) if "@" in a)
    scans = "20" if "scenario.num_scans=20" in argv else "100"
    assert len(err) == 1 and f"--fault {fault}:" in err[0], err
    assert f"has {scans} scans" in err[0]
    assert not (tmp_path / "run").exists()


def test_fault_before_the_last_scan_passes_the_check(capsys):
    """kill:s2@99 of 100 scans gets past the scan check (--sim then refuses process faults)."""
    assert main(["run", "--sim", "--fault", "kill:s2@99"]) == 2
    assert "needs real processes" in capsys.readouterr().err


class _Started(Exception):
    pass


@pytest.mark.parametrize("flags, secure, routed", [
    ([], False, False),
    (["--secure"], True, False),
    (["--router"], False, True),
    (["--router", "--secure"], True, True),
    (["--set", "network.router=true"], False, True),
])
def test_run_says_at_start_when_it_is_secure_or_routed(flags, secure, routed, tmp_path,
                                                       monkeypatch, capsys):
    """A secure run says so (and where its keys are), a routed run says where its router
    listens, each in one line at start; a plain run says neither."""
    import types

    import sensornet.sim.run.launcher

    def fake_start_run(*a, **kw):  # the processes are not started: only what cmd_run says
        ep = ("tls" if kw["secure"] else "tcp") + "/127.0.0.1:7999"
        return types.SimpleNamespace(endpoints={"router": ep} if kw["router"] else {})

    def fake_wait_run(*a, **kw):
        raise _Started

    monkeypatch.setattr(sensornet.sim.run.launcher, "start_run", fake_start_run)
    monkeypatch.setattr(sensornet.sim.run.launcher, "wait_run", fake_wait_run)
    out = tmp_path / "run"
    with pytest.raises(_Started):
        main(["run", "seed000", "--no-rerun", "--out", str(out), *flags])
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("run seed000: world + 3 peers")
    said = [ln for ln in lines if ln.startswith("secure mode:")]
    assert len(said) == int(secure), lines
    if secure:
        assert "mutual TLS + access control" in said[0] and f"keys in {out / 'keys'}" in said[0]
        assert (out / "keys" / "ca.pem").is_file()
    said = [ln for ln in lines if ln.startswith("routed")]
    assert len(said) == int(routed), lines
    if routed:
        assert said[0].endswith(("tls" if secure else "tcp") + "/127.0.0.1:7999")
        assert any("network.router" in f for f in flags) == ("[network] router = true" in said[0])


def test_run_sim_prints_the_summary(capsys):
    assert main(["run", "--sim", "--set", "birth.model=truth",
                 "--set", "scenario.num_scans=30"]) == 0
    out = capsys.readouterr().out
    assert "| s1 | 30 |" in out and "| s3 | 30 |" in out


def test_scenario_show_round_trips(capsys):
    assert main(["scenario", "show", "seed000"]) == 0
    assert capsys.readouterr().out == scenario_text("seed000")


def test_run_summary_table_shows_where_the_latency_goes():
    from sensornet.sim.run.launcher import format_summary

    base = {"scans": 10, "mean_ospa_local": 30.0, "mean_ospa_fused": 20.0, "messages_sent": 20,
            "messages_received": 40, "bytes_sent": 4000, "bytes_received": 8000,
            "rejected_total": 0, "mean_estimate_age": 0.0, "latency_ms_median": 4.0,
            "latency_ms_p99": 7.0}
    with_parts = dict(base, latency_breakdown_ms_median={
        "transit": 0.8, "local": 0.9, "fusion_wait": 2.3, "neighbours": 1.7, "fusing": 0.6})
    text = format_summary({"s1": with_parts, "s2": dict(base)})
    assert "| s1 | 0.80 | 0.90 | 1.70 | 0.60 |" in text
    assert "| s2 | - | - | - | - |" in text  # a peer without a breakdown (e.g. an old summary)
    assert "Where the latency goes" not in format_summary({"s2": dict(base)})
