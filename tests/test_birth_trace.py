"""sim.studies.labelled.birth_trace: first-track lags and the fused-late target-scans by the
inputs that held the target (issue 33), on a hand-built record."""

import numpy as np
from sensornet.sim.studies.labelled.birth_trace import held_near, lags, late_cases
from sensornet.tracking.mixture import GaussianMixture
from sensornet.tracking.track_metrics import TrackTable


def _mix(w, xy):
    xy = np.asarray(xy, float).reshape(-1, 2)
    means = np.zeros((len(xy), 4))
    means[:, [0, 2]] = xy
    return GaussianMixture(np.asarray(w, float), means, np.tile(np.eye(4), (len(xy), 1, 1)))


def _state(xy):
    s = np.zeros((len(xy), 4))
    s[:, [0, 2]] = xy
    return s


def _record():
    """One target at (0, 0) over scans 1-4; the centralised has it from scan 2, peer a's local
    from 3 and its fused from 4; at scans 2 and 3 its inputs hold 0.7 + 0.2 and 0.3 of it."""
    T = TrackTable([1, 2, 3, 4], [0, 0, 0, 0], [[0, 0]] * 4)
    central = TrackTable([2, 3, 4], [5, 5, 5], [[10, 0]] * 3)
    local = TrackTable([3, 4], [1, 1], [[5, 5]] * 2)
    fused = TrackTable([4], [2], [[0, 3]])
    far = _mix([0.9], [[400, 0]])  # mass of another target: not near
    calls = [dict(k=2, states=np.zeros((0, 4)), mixes=[_mix([0.7, 0.9], [[20, 0], [500, 0]]),
                                                        _mix([0.2], [[0, 30]]), far]),
             dict(k=3, states=_state([[300, 300]]), mixes=[_mix([0.3], [[0, 0]]), far, far]),
             dict(k=4, states=_state([[0, 3]]), mixes=[_mix([0.9], [[0, 0]]), far, far])]
    return dict(T=T, central=central, local={"a": local}, fused={"a": fused}, names=["a"],
                calls={"a": calls})


def test_held_near_sums_each_inputs_mass_within_a_quarter_of_the_cutoff():
    y = np.array([[0.0, 0.0], [500.0, 0.0]])
    got = held_near([_mix([0.7, 0.9], [[20, 0], [500, 0]]), _mix([0.2, 0.1], [[0, 49], [0, 51]])],
                    y)
    np.testing.assert_allclose(got, [[0.7, 0.9], [0.2, 0.0]])


def test_lags_count_scans_from_birth_to_the_first_track_near():
    got = lags(_record())
    assert got["central"].tolist() == [1]
    assert got["local"].tolist() == [[2]]
    assert got["fused"].tolist() == [[3]]


def test_late_cases_are_split_by_the_inputs_holding_the_target_and_its_age():
    by_held, by_age = late_cases(_record())
    # scan 2: two inputs hold it, the heaviest 0.7; scan 3: one input at 0.3; scan 4: fused has it
    assert by_held == {(2, True): 1, (1, False): 1}
    assert by_age == {1: 1, 2: 1}


def test_a_target_never_reached_has_no_lag_even_when_born_late():
    """A target born at scan 5 of 10 that no estimate ever reaches is NaN ("never"), not the
    scans left in the run (5 < the run's length, which once counted it as reached)."""
    T = TrackTable([1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 5, 6, 7, 8, 9, 10],
                   [0] * 10 + [1] * 6, [[0, 0]] * 10 + [[5000, 5000]] * 6)
    near_first = TrackTable([2, 3], [7, 7], [[0, 0]] * 2)
    rec = dict(T=T, central=near_first, local={"a": near_first}, fused={"a": near_first},
               names=["a"], calls={"a": []})
    got = lags(rec)
    assert got["central"][0] == 1 and np.isnan(got["central"][1])
    assert got["fused"][0, 0] == 1 and np.isnan(got["fused"][0, 1])
