"""The choices of the scenario keys the command line offers too (``--fusion``, ``--omega``,
``--policy``, ``--birth``), declared once: the scenario's fields (:mod:`sim.scenario.model`)
name them in their declaration and the parser (:mod:`sensornet.cli.parser`) offers them.

No imports, on purpose (as :mod:`sim.bounds`): ``sensornet --help`` shows them without loading
NumPy or the scenario package. The peer kinds (``network.filter``, ``--filter``) come from
their own light registry, :func:`sim.kinds.names`.
"""

MIXTURE_RULES = ("hybrid", "gci", "aa", "none")
"""``fusion.rule`` values that combine Gaussian mixtures (GM-PHD peers, the offline experiment):
``"hybrid"`` (AA target weights, GCI locations), ``"gci"``, ``"aa"`` or ``"none"``."""
FUSION_RULES = ("gci", "aa", "hybrid", "ratio", "none")
"""Every ``fusion.rule``: the mixture rules and ``"ratio"`` (the particle rule, IMM peers)."""
OMEGA_RULES = ("metropolis", "uniform", "det", "chernoff")
"""Fusion weights (``network.omega``, ``fusion.fusing_omega``): Metropolis, uniform, or
optimised per fusion (``"det"``: smallest determinant, ``"chernoff"``: Chernoff point)."""
OOS_POLICIES = ("nale", "drop-late", "as-is")
"""``network.policy``: what a peer does with an estimate older than its scan."""
BIRTH_MODELS = ("paper", "truth", "measurements")
"""``birth.model``: the printed components, one at each true start, or at the previous scan's
unexplained plots (``sim.world.birth``)."""
