"""The live view on a real map (issue 34 item 5, :mod:`sensornet.view_map`): truth, sites and
fused tracks of a scenario with a geographic origin in WGS84, converted back from the local
frame with the loader's library (pymap3d), batched per entity; the map view only when the
scenario has such an origin."""

from __future__ import annotations

import subprocess
from dataclasses import replace

import numpy as np
import pymap3d
import pytest
import rerun as rr
import rerun.blueprint as rrb
from pymap3d import vincenty
from sensornet.peers.rerun_layout import TRUTH_COLOR, default_blueprint
from sensornet.protocol.messages import Tracks, Truth
from sensornet.sim.scenario import load_scenario
from sensornet.sim.traffic.opensky import LocalFrame
from sensornet.sim.traffic.recorded import recorded_world

from sensornet.view import Batcher
from sensornet.view_map import GeoViewState, circle, geo_frame, geo_map, lat_lon
from sensornet.view_map_figure import plot_map, read_map, track_lines
from sensornet.view_state import id_color
from tests.processes import end_once_view_drew, env, rerun_exe, sensornet

PARIS = LocalFrame(48.868, 2.456, 0.0)


class _Rec:
    """A recording stream that keeps what it is sent: columns by entity, static logs."""

    def __init__(self) -> None:
        self.columns: dict[str, tuple[list[int], dict]] = {}
        self.logs: dict[str, object] = {}
        self.times: dict[str, int] = {}

    def send_columns(self, path, indexes, columns):
        scans = indexes[0].as_arrow_array().to_pylist()
        self.columns[path] = (scans, {str(c.component_descriptor()).split(":")[-1]:
                                      c.as_arrow_array().to_pylist() for c in columns})

    def log(self, path, archetype, static=False):
        assert static, path
        self.logs[path] = archetype
        self.times[path] = self.times.get(path, 0) + 1


def _rgba(c) -> int:
    r, g, b = (int(v) for v in c)
    return (r << 24) | (g << 16) | (b << 8) | 255


def _east_north(ll: np.ndarray) -> np.ndarray:
    """East and north (m) in the Paris frame of [lat, lon] points at height 0 (pymap3d)."""
    e, n, _ = pymap3d.geodetic2enu(ll[:, 0], ll[:, 1], 0.0, PARIS.lat0, PARIS.lon0, 0.0)
    return np.column_stack([e, n])


def test_the_conversion_inverts_the_loaders_frame():
    """Points within 100 km of the Paris centre: the loader's to_enu with up dropped, then
    lat_lon, returns them to 1e-6 degrees; and lat_lon's points are at height 0 with the east
    and north asked for (pymap3d's geodetic2enu, to 1 mm)."""
    rng = np.random.default_rng(0)
    lat = PARIS.lat0 + rng.uniform(-0.9, 0.9, 200)
    lon = PARIS.lon0 + rng.uniform(-1.3, 1.3, 200)
    enu = PARIS.to_enu(lat, lon, 0.0)
    assert np.abs(enu[:, 2]).max() > 100  # the dropped up coordinate is not small
    back = lat_lon(PARIS, enu[:, :2])
    assert np.abs(back - np.column_stack([lat, lon])).max() < 1e-6
    xy = rng.uniform(-4e5, 4e5, (50, 2))
    np.testing.assert_allclose(_east_north(lat_lon(PARIS, xy)), xy, rtol=0, atol=1e-3)
    assert lat_lon(PARIS, np.zeros((0, 2))).shape == (0, 2)


def test_a_range_circle_is_geodesic():
    """Every point of a circle is its radius from the centre (Vincenty's inverse problem)."""
    c = circle(49.0097, 2.5479, 111_000.0)
    dist, _ = vincenty.vdist(49.0097, 2.5479, c[:, 0], c[:, 1])
    np.testing.assert_allclose(dist, 111_000.0, rtol=1e-6)
    assert np.array_equal(c[0], c[-1])
    with pytest.raises(ValueError, match="radius_m"):
        circle(49.0, 2.5, 0.0)


def test_the_geographic_origin_is_the_loaders():
    """paris: the frame the loader put the aircraft in, sites back at their latitude and
    longitude; a synthetic scenario has none."""
    scn = load_scenario("paris")
    geo = geo_map(scn)
    assert geo is not None and geo.frame == recorded_world(scn).frame == geo_frame(scn)
    for s in scn.sensors:
        assert np.abs(np.subtract(geo.sites[s.name], s.site)).max() < 1e-6, s.name
        assert geo.ranges[s.name] == s.max_range
    assert geo.radius == scn.traffic.radius
    assert geo_map(load_scenario("seed000")) is None
    # no traffic.centre: the loader's frame at the middle of the reports' box
    bare = replace(scn, traffic=replace(scn.traffic, centre=None, radius=None))
    frame = geo_frame(bare)
    assert frame == recorded_world(bare).frame and frame != geo.frame


def _views(item) -> list[str]:
    """The class names of every view in a blueprint or container."""
    if isinstance(item, rrb.Blueprint):
        return _views(item.root_container)
    if isinstance(item, rrb.Container):
        return [v for c in item.contents for v in _views(c)]
    return [type(item).__name__]


def test_the_blueprint_has_a_map_view_only_with_a_geographic_origin():
    for name, maps in (("paris", 1), ("seed000", 0), ("seed001", 0)):
        scn = load_scenario(name)
        views = _views(default_blueprint(scn.sensor_names, geo=geo_map(scn) is not None))
        assert views.count("MapView") == maps, (name, views)
        assert views.count("Spatial2DView") >= 1, name  # the local map stays


def test_truth_sites_and_tracks_on_the_map():
    """Two aircraft and one labelled and one unlabelled peer's track over three scans: one
    call per entity per flush, lat/lon as pymap3d puts the local points, class ids named by
    icao24, track id and site name, trails per track id."""
    scn = load_scenario("paris")
    rec = _Rec()
    state = GeoViewState(Batcher(rr, rec), scn.sensor_names, 2.0, geo=geo_map(scn))
    ids = np.array([0x3C6444, 0x4CA7B5])
    for k in (1, 2, 3):
        X = np.array([[1000.0 * k, 500, 2000, 0], [-5000, 0, 300.0 * k, 150]])
        state.message(Truth(k, ids, X))
        state.message(Tracks("cdg", k, X[:1] + 10.0, ids=np.array([[1, 7, 0]])))
        state.message(Tracks("orly", k, np.array([[10.0 * k, 0, -20, 0]])))
    state.b.flush()
    cols = rec.columns
    assert set(cols) >= {"map/truth", "map/truth/paths", "map/peers/cdg/tracks",
                         "map/peers/cdg/trails", "map/peers/orly/tracks"}
    scans, truth = cols["map/truth"]
    assert scans == [1, 2, 3]
    np.testing.assert_allclose(_east_north(np.array(truth["positions"][2])), X[:, [0, 2]],
                               rtol=0, atol=1e-3)
    assert truth["colors"][2] == [_rgba(TRUTH_COLOR)] * 2
    names = _classes(rec)
    assert rec.times["map"] == 2  # the sites' names when made, the rest once at the flush
    assert truth["class_ids"][2] == [names["3c6444"], names["4ca7b5"]]
    paths = np.array(cols["map/truth/paths"][1]["line_strings"][2])  # 2 aircraft x 3 scans
    np.testing.assert_allclose(_east_north(paths[1]), [[-5000.0, 300], [-5000, 600],
                                                       [-5000, 900]], rtol=0, atol=1e-3)
    _, cdg = cols["map/peers/cdg/tracks"]
    np.testing.assert_allclose(_east_north(np.array(cdg["positions"][0])), [[1010.0, 2010]],
                               rtol=0, atol=1e-3)
    assert cdg["colors"][0] == [_rgba(id_color(np.array([[1, 7, 0]]))[0])]
    assert cdg["class_ids"][0] == [names["1.7.0"]]
    trail = cols["map/peers/cdg/trails"][1]["line_strings"]
    assert [len(t) for t in trail] == [0, 1, 1] and len(trail[2][0]) == 3
    orly = cols["map/peers/orly/tracks"][1]["class_ids"]
    assert orly == [[names["orly/0"]]] * 3  # the 2-D map's display number, kept
    sites = rec.logs["map/sensors"].positions.as_arrow_array().to_pylist()
    np.testing.assert_allclose(sites, [s.site for s in scn.sensors], atol=1e-6)
    assert "map/sensors/coverage" in rec.logs and "map/region" in rec.logs
    assert {"cdg", "orly", "north", "south"} <= set(names)


def _classes(rec: _Rec) -> dict[str, int]:
    """Name -> class id, from the annotation context last logged at ``map``."""
    ctx = rec.logs["map"].context.as_arrow_array().to_pylist()[0]
    return {c["class_description"]["info"]["label"]: c["class_id"] for c in ctx}


def test_the_figure_reads_back_what_the_view_recorded(tmp_path):
    """A view's .rrd written in-process: read_map returns the logged lat/lon and names, the
    tracks grouped per id in scan order, and plot_map draws them; bad input: one line."""
    scn = load_scenario("paris")
    path = tmp_path / "v.rrd"
    stream = rr.RecordingStream("sensornet-test", recording_id="map-test")
    stream.set_sinks(rr.FileSink(str(path)))
    state = GeoViewState(Batcher(rr, stream), scn.sensor_names, 2.0, geo=geo_map(scn))
    for k in range(1, 5):
        X = np.array([[800.0 * k, 400, 100, 0], [-3000, 0, 400.0 * k, 200]])
        state.message(Truth(k, np.array([0x3C6444, 0x4CA7B5]), X))
        state.message(Tracks("cdg", k, X + 5.0, ids=np.array([[1, 1, 0], [1, 2, 0]])))
    state.b.flush()
    stream.flush()
    stream.disconnect()
    rec = read_map(path)
    assert rec.peers() == ["cdg"] and sorted(rec.rows["/map/truth"]) == [1, 2, 3, 4]
    names = rec.names()
    assert {names[c] for c in rec.rows["/map/truth"][4]["GeoPoints:class_ids"]} == {
        "3c6444", "4ca7b5"}
    np.testing.assert_allclose(_east_north(np.array(
        rec.rows["/map/truth"][4]["GeoPoints:positions"])), X[:, [0, 2]], atol=1e-3)
    lines = track_lines(rec.rows["/map/peers/cdg/tracks"])
    assert sorted(names[i] for i, _, _ in lines) == ["1.1.0", "1.2.0"]
    for i, ll, _ in lines:
        j = 0 if names[i] == "1.1.0" else 1
        want = np.array([[800.0 * k + 5 if j == 0 else -2995, 105 if j == 0 else 400.0 * k + 5]
                         for k in range(1, 5)])
        np.testing.assert_allclose(_east_north(ll), want, atol=1e-3)
    out = plot_map(rec, "cdg", tmp_path / "map.png")
    assert out.stat().st_size > 10_000
    with pytest.raises(ValueError, match="--peer orly: no tracks"):
        plot_map(rec, "orly", tmp_path / "x.png")
    plain = tmp_path / "plain.rrd"
    other = rr.RecordingStream("sensornet-test", recording_id="plain")
    other.set_sinks(rr.FileSink(str(plain)))
    other.log("world/truth", rr.Points2D([[0.0, 0.0]]), static=True)
    other.flush()
    other.disconnect()
    with pytest.raises(ValueError, match="plain.rrd: no map"):
        read_map(plain)


@pytest.mark.network
def test_a_paris_run_records_the_map(tmp_path):
    """``sensornet run paris`` (processes, the view on): the run's recording verifies and holds
    the map's entities, as GeoPoints and GeoLineStrings. The run (its 300 ticks, 60 s at its
    speed) ends once its view says it drew every peer (its world's SIGTERM): 12 ticks took
    2.4 s, and a view that imports for seconds longer than the peers on a busy machine
    linked after their end."""
    out = tmp_path / "run"
    with sensornet(["run", "paris", "--viewer", "none", "--out", str(out)], tmp_path) as run:
        end_once_view_drew(run, out, load_scenario("paris").sensor_names)
        _, err = run.proc.communicate(timeout=300)
    assert run.proc.returncode == 0, err[-2000:]
    path = out / "recording.rrd"
    check = subprocess.run([rerun_exe(), "rrd", "verify", str(path)], capture_output=True,
                           text=True, timeout=120, env=env())
    assert check.returncode == 0, check.stderr
    text = subprocess.run([rerun_exe(), "rrd", "print", "-v", str(path)], capture_output=True,
                          text=True, timeout=120, env=env()).stdout
    for entity in ("/map/truth", "/map/truth/paths", "/map/sensors", "/map/sensors/coverage",
                   "/map/region", "/map/peers/cdg/tracks", "/map/peers/south/trails"):
        assert entity in text, entity
    assert "GeoPoints:positions" in text and "GeoLineStrings:line_strings" in text
    assert "MapZoom" in text  # the blueprint's map view
