"""Replay a recorded peer: rebuild it from the scenario stored in the recording (plus
``--set`` what-ifs) and feed it its recorded inputs (:func:`peers.recording.replay_with`)."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from sensornet.peers.core import PeerCore
from sensornet.peers.recording import Replay, replay_with
from sensornet.sim.run.peers import make_peer
from sensornet.sim.scenario import load_scenario, parse_overrides


def _builder(overrides: list[str]):
    """The peer factory for a recording's metadata, ``overrides`` on top of the recorded ones."""

    def build(meta: dict[str, str]) -> PeerCore:
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / meta.get("scenario_file", "scenario.toml")
            src.write_text(meta["scenario_text"])
            recorded = json.loads(meta.get("overrides", "[]"))
            scn = load_scenario(str(src), overrides=parse_overrides([*recorded, *overrides]))
            if overrides:
                was = load_scenario(str(src), overrides=parse_overrides(recorded)).network.rounds
                if scn.network.rounds != was:
                    raise ValueError(
                        f"--set network.rounds={scn.network.rounds}: the recording holds only "
                        f"the {was} round(s) per scan the run had, and a replay cannot make the "
                        f"neighbours' other rounds (run again with --set "
                        f"network.rounds={scn.network.rounds})")
        speed = float(meta["speed"]) if meta.get("speed") else None
        return make_peer(scn, meta["peer"], int(meta.get("run", 0)), network=meta["network"],
                         speed=speed)

    return build


def replay(path: Path, overrides: list[str] = ()) -> Replay:
    """Feed a recording through a freshly built peer (``overrides``: ``--set`` items on top of
    the recorded ones)."""
    return replay_with(path, _builder(list(overrides)))
