"""sensornet: peer-to-peer multi-sensor multi-target tracking.

The subpackages ``sensornet.tracking``, ``sensornet.protocol``, ``sensornet.peers`` and
``sensornet.sim`` live in the checkout's top-level folders of those names; an installed wheel
holds them inside this package (pyproject's package-dir). In a checkout (an editable install,
or tests run from its root) this package's path also covers the checkout's root, so the same
names resolve to those folders."""

from pathlib import Path as _Path

_here = _Path(__file__).resolve().parent
if not (_here / "peers").is_dir() and (_here.parent / "peers" / "core.py").is_file():
    __path__.append(str(_here.parent))  # noqa: F821 (the package's own __path__)
del _Path, _here
