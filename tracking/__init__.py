"""Pure estimation core: Gaussian mixtures, GM-PHD, fusion, NALE, metrics. No I/O."""

from sensornet.tracking.mixture import GaussianMixture

__all__ = ["GaussianMixture"]
