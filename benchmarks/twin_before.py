"""The peer logic's hot-path modules as they were before issue 23's per-call work (commit
d7f97c4), served from the repository's history under their own names (``tracking.fusion``,
``protocol.codec``, ...): ``install()`` in a fresh process, before anything imports them, and
the twin there runs the old code. The same-run 'before' of ``bench_twin_cpu.py``. No copy is
kept in the tree; ``git`` and the clone's history are needed."""

from __future__ import annotations

import importlib.abc
import importlib.util
import sys

from benchmarks.history import old_source

COMMIT = "d7f97c4"
MODULES = ("sensornet.tracking.fusion", "sensornet.tracking.reduction",
           "sensornet.tracking.gaussian", "sensornet.tracking.mixture",
           "sensornet.protocol.codec", "sensornet.peers.core", "sensornet.peers.scoring")
"""The modules the speed work changes (the rest of the tree is shared by both sides)."""


def _source(name: str) -> str:
    return old_source(COMMIT, name.removeprefix("sensornet.").replace(".", "/") + ".py",
                      "twin_before")


class _Before(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds :data:`MODULES` and executes their source at :data:`COMMIT`."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname in MODULES:
            return importlib.util.spec_from_loader(fullname, self, origin=f"{COMMIT}:{fullname}")
        return None

    def create_module(self, spec):
        return None

    def exec_module(self, module) -> None:
        code = compile(_source(module.__name__), f"{COMMIT}:{module.__name__}", "exec")
        exec(code, module.__dict__)


def install() -> None:
    """Serve :data:`MODULES` from :data:`COMMIT` in this process (none may be imported yet)."""
    loaded = [m for m in MODULES if m in sys.modules]
    if loaded:
        raise RuntimeError(f"already imported: {loaded}")
    sys.meta_path.insert(0, _Before())
