"""Moved to :mod:`peers.faultplan` (the plan is read by the peer's fault injector, a layer
below ``sim``); this name stays importable for modules not yet moved over."""

from peers.faultplan import *  # noqa: F403
from peers.faultplan import __all__  # noqa: F401
