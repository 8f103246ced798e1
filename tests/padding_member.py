"""A padding member as a real process (issue 36): ``sensornet peer`` whose every estimate is its
real one padded with negligible-weight components up to the codec's limit, signed with its own
key in secure mode, each sent ``copies`` times (1: one per scan and round, as an honest peer;
4: the whole message rate the receivers' buckets allow, :mod:`peers.admission`).

Used by ``tests/test_member_costs.py`` and ``benchmarks/bench_member_costs.py``:
:func:`start_padded_run` is :func:`sim.run.launcher.start_run` with the liars' commands
replaced by this file's entry point, which wraps the peer's core in
:class:`sim.run.lies.LyingCore` and then runs the ``sensornet`` command unchanged::

    python tests/padding_member.py PAD COPIES SEED -- peer s2 --scenario seed000 ...
"""

from __future__ import annotations

import sys
from pathlib import Path

if __name__ == "__main__":  # run as a file by the launcher: the checkout's tests package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
import sensornet.sim.run.launcher as launcher
from sensornet.peers.core import PeerCore
from sensornet.protocol.codec import DEFAULT_LIMITS
from sensornet.protocol.messages import Estimate
from sensornet.sim.run.lies import Lie, LyingCore
from sensornet.tracking.mixture import GaussianMixture

import sensornet.cli.commands.peer as peer_cmd
from sensornet.cli import main as cli_main

PAD = DEFAULT_LIMITS.max_components
"""The codec's component limit (2,000): what a padding member fills each estimate to."""
PAD_WEIGHT = 1e-4
"""Weight of each padding component: negligible (an honest peer's level-2 pruning drops
everything at or under 0.5, so it never sends one)."""
PAD_VARIANCE = 100.0
"""Variance (m^2, (m/s)^2) on the diagonal of each padding component's covariance."""


def padding(n: int, region, rng: np.random.Generator,
            position_index: tuple[int, int] = (0, 2)) -> Lie:
    """The lie: the real mixture plus ``n - len(mixture)`` components of weight
    :data:`PAD_WEIGHT`, positions uniform over ``region`` ``[[x0, x1], [y0, y1]]``."""
    (x0, x1), (y0, y1) = region
    ix, iy = position_index

    def lie(mix: GaussianMixture, k: int = 0) -> GaussianMixture:
        m = max(0, n - len(mix))
        means = np.zeros((m, mix.dim))
        means[:, ix], means[:, iy] = rng.uniform(x0, x1, m), rng.uniform(y0, y1, m)
        extra = GaussianMixture(np.full(m, PAD_WEIGHT), means,
                                np.tile(PAD_VARIANCE * np.eye(mix.dim), (m, 1, 1)))
        return GaussianMixture.concatenate([mix, extra])
    return lie


class RepeatingLiar(LyingCore):
    """A :class:`LyingCore` that publishes every estimate ``copies`` times (each told and, in
    secure mode, sealed anew: a fresh stamp, not a replay)."""

    def __init__(self, core: PeerCore, lie: Lie, copies: int) -> None:
        if copies < 1:
            raise ValueError(f"copies must be >= 1, got {copies}")
        super().__init__(core, lie)
        self.copies = copies

    def _wrap(self, messages: list):
        return super()._wrap([m for m in messages
                              for _ in range(self.copies if type(m) is Estimate else 1)])


def padded_core(core: PeerCore, scn, pad: int, copies: int, seed: int) -> RepeatingLiar:
    """``core`` (made by :func:`sim.run.peers.make_peer` for ``scn``) as a padding member."""
    return RepeatingLiar(core, padding(pad, scn.region, np.random.default_rng(seed)), copies)


def start_padded_run(scn, source: str, out: Path, liars: dict[str, tuple[int, int]],
                     seed: int = 36, nice: int = 0, **kw):
    """:func:`sim.run.launcher.start_run` (``kw`` its arguments) with each peer of ``liars``
    ``{name: (pad, copies)}`` started as a padding member (this file's entry point);
    ``nice``: their nice value (on one machine, a positive one keeps their own extra work off
    the honest peers' CPU, as if each member had a machine of its own)."""
    unknown = sorted(set(liars) - set(scn.sensor_names))
    if unknown:
        raise ValueError(f"liars {unknown} are not sensors of {scn.name!r}")
    original = launcher._peer_commands
    prefix = launcher._cli()

    def commands(*a, **k):
        cmds = original(*a, **k)
        for name, (pad, copies) in liars.items():
            cmd = cmds[name]
            assert cmd[:len(prefix)] == prefix, cmd
            entry = [sys.executable, str(Path(__file__).resolve()), str(pad), str(copies),
                     str(seed), "--"]
            cmds[name] = [*(["nice", "-n", str(nice)] if nice else []), *entry,
                          *cmd[len(prefix):]]
        return cmds

    launcher._peer_commands = commands
    try:
        return launcher.start_run(scn, source, out, **kw)
    finally:
        launcher._peer_commands = original


def main(argv: list[str]) -> int:
    """``PAD COPIES SEED -- <sensornet arguments>``: run ``sensornet`` with every peer it
    makes a padding member."""
    pad, copies, seed = (int(x) for x in argv[:3])
    if argv[3] != "--":
        raise ValueError(f"expected '--' after PAD COPIES SEED, got {argv[3]!r}")
    make = peer_cmd.make_peer

    def make_padded(scn, name, *a, **k):
        return padded_core(make(scn, name, *a, **k), scn, pad, copies, seed)

    peer_cmd.make_peer = make_padded
    return cli_main(argv[4:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
