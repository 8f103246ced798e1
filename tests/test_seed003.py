"""Seed 003 scenario and Monte Carlo plumbing (sim/studies/seed003/montecarlo.py)."""

from __future__ import annotations

import numpy as np
import pytest
from sensornet.sim.studies.seed003 import montecarlo as seed003
from sensornet.tracking.imm import POS, VEL


def test_truth_is_the_coordinated_90_degree_turn():
    cfg = seed003.load()
    X = seed003.truth(cfg)
    assert X.shape == (101, 6)
    np.testing.assert_allclose(X[50, [0, 3]], [25000.0, 5000.0])
    np.testing.assert_allclose(np.hypot(X[:, VEL[0]], X[:, VEL[1]]), 500.0)
    np.testing.assert_allclose(X[70, list(VEL)], [0.0, 500.0], atol=1e-9)
    # turn radius v / omega = 500 / (pi / 40): the centre is (25000, 5000 + r)
    r = 500 / (np.pi / 40)
    np.testing.assert_allclose(X[70, list(POS)], [25000 + r, 5000 + r])
    np.testing.assert_allclose(np.hypot(X[60, 2], X[60, 5]), 500 * np.pi / 40)  # ~4 g


def test_literal_variant_keeps_vx_and_gains_5g():
    cfg = seed003.load(overrides={"scenario.manoeuvre": "literal"})
    X = seed003.truth(cfg)
    np.testing.assert_allclose(X[70, list(VEL)], [500.0, 20 * 5 * seed003.G0])
    np.testing.assert_allclose(X[100, VEL[1]], 20 * 5 * seed003.G0)


def test_turn_model_at_the_true_rate_reproduces_the_truth():
    cfg = seed003.load()
    X = seed003.truth(cfg)
    F, _ = seed003.coordinated_turn(1.0, np.pi / 40, 1.0)
    idx = [0, 1, 3, 4]
    for k in range(51, 71):
        np.testing.assert_allclose((F @ X[k - 1])[idx], X[k, idx], atol=1e-8)


def test_clutter_density_puts_in_gate_returns_in_the_steady_state_gate():
    cfg = seed003.load()
    s1 = seed003.sensors(cfg)[0]
    S = seed003.cv_steady_state_S(cfg, 50.0)
    assert s1.clutter_density * s1.gate_volume(S) == pytest.approx(2.0)
    # the DARE solution is the fixed point of the Riccati recursion
    from sensornet.tracking.imm import constant_velocity
    m = constant_velocity(1.0, cfg["filters"]["sigma_cv"])
    i = [0, 1, 3, 4]
    F, Q, H = m.F[np.ix_(i, i)], m.Q[np.ix_(i, i)], seed003.H6[:, i]
    P = np.eye(4) * 1e4
    for _ in range(500):
        Sk = H @ P @ H.T + 2500 * np.eye(2)
        K = P @ H.T @ np.linalg.inv(Sk)
        P = F @ (P - K @ Sk @ K.T) @ F.T + Q
    np.testing.assert_allclose(S, H @ P @ H.T + 2500 * np.eye(2), rtol=1e-6, atol=1e-6)


def test_gate_clutter_is_uniform_in_the_gate():
    rng = np.random.default_rng(1)
    S = np.array([[900.0, 300.0], [300.0, 1600.0]])
    gamma = 9.21
    z = seed003.gate_clutter(np.array([10.0, -5.0]), S, gamma, 20000, rng)
    nu = z - [10.0, -5.0]
    g = np.einsum("mi,ij,mj->m", nu, np.linalg.inv(S), nu)
    assert g.max() < gamma
    # uniform in an ellipse: g / gamma is uniform on (0, 1)
    assert np.mean(g / gamma) == pytest.approx(0.5, abs=0.01)
    assert np.mean(g / gamma < 0.25) == pytest.approx(0.25, abs=0.01)


def test_lost_needs_consecutive_scans():
    e = np.array([0, 2000, 2000, 0, 2000, 2000, 2000, 0.0])
    assert not seed003.lost(e, 1000, 4)
    assert seed003.lost(e, 1000, 3)


def test_one_run_gives_every_row_and_same_draws_give_same_numbers():
    cfg = seed003.load()
    a = seed003.run_once(cfg, 10000, methods=("IMM-PDAF", "fuzzy IMM"))
    b = seed003.run_once(cfg, 10000, methods=("IMM-PDAF", "fuzzy IMM"))
    assert set(a.pos_err) == {("IMM-PDAF", 1), ("IMM-PDAF", 2), ("fuzzy IMM", 1),
                              ("fuzzy IMM", 2)}
    for key in a.pos_err:
        np.testing.assert_array_equal(a.pos_err[key], b.pos_err[key])
    rows = seed003.summarise(cfg, [a, b])
    assert len(rows) == 4 and rows[0]["runs"] == 2
    assert "det_hit" in rows[2] and "det_hit" not in rows[0]
    text = seed003.format_table(rows)
    assert "fuzzy IMM" in text


def test_unknown_setting_is_refused_in_one_line(capsys):
    assert seed003.main(["--runs", "1", "--set", "clutter.density=3"]) == 2
    assert "unknown setting 'clutter.density'" in capsys.readouterr().err


def test_network_loader_builds_pda_peers_from_the_seed_file():
    """seed003 is a plain scenario file of the one model: its peers are PDA peers."""
    from sensornet.sim.scenario import load_scenario

    scenario = load_scenario("seed003")
    assert scenario.network.filter == "pda"
    assert len(scenario.sensors) >= 2


def test_csv_and_png_outputs(tmp_path, capsys):
    assert seed003.main(["--runs", "1", "--first-run", "10000", "--quiet", "--methods",
                         "IMM-PDAF", "--csv", str(tmp_path)]) == 0
    table = (tmp_path / "seed003_table.csv").read_text().splitlines()
    assert table[0].startswith("method,sensors,runs,lost") and len(table) == 3
    rmse = (tmp_path / "seed003_rmse.csv").read_text().splitlines()
    assert rmse[0] == "scan,IMM-PDAF x1,IMM-PDAF x2" and len(rmse) == 101
    assert (tmp_path / "seed003_rmse.png").read_bytes()[:4] == b"\x89PNG"
