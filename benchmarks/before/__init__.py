"""The GM-PHD modules as they were before issue 15's speed work (commit fea5bab), read from the
repository's history and loaded as ``benchmarks.before.mixture / reduction / gmphd`` (their
imports of each other pointed here): the same-run reference of ``bench_gmphd_stonesoup.py``.
No copy is kept in the tree; ``git`` and the clone's history are needed."""

from __future__ import annotations

import importlib.util
import sys

from benchmarks.history import old_source

COMMIT = "fea5bab"
MODULES = ("mixture", "reduction", "gmphd")  # in dependency order


def _source(name: str) -> str:
    text = old_source(COMMIT, f"tracking/{name}.py", "benchmarks.before")
    for dep in MODULES:
        text = text.replace(f"from sensornet.tracking.{dep} import",
                            f"from {__name__}.{dep} import")
    return text


for _name in MODULES:
    _full = f"{__name__}.{_name}"
    _spec = importlib.util.spec_from_loader(_full, loader=None, origin=f"{COMMIT}:tracking")
    _module = importlib.util.module_from_spec(_spec)
    sys.modules[_full] = _module
    exec(compile(_source(_name), f"{COMMIT}:tracking/{_name}.py", "exec"), _module.__dict__)
    globals()[_name] = _module
