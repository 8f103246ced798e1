"""The bounds every input is checked against: scenario files, overrides and command-line flags.

No imports, on purpose: the command line's parser shows and checks them before anything heavy
(NumPy, SciPy, the scenario loader) is loaded, so ``sensornet --help`` stays quick.
"""

MAX_SENSORS = 256
"""Sensors (= peers) a scenario may list: a flooding forward carries at most this many scans
(protocol.codec.Limits.max_entries), and a peer's work per scan grows with its neighbours."""
MAX_ROUNDS = 16
"""``network.rounds``: consensus (or flooding) rounds per scan. Every round is a message per
peer and link held until the scan is done, so the twin's memory grows with it."""
MAX_RUNS = 100_000
"""Monte Carlo runs one command or campaign cell may ask for (``--runs``, ``campaign.runs``):
each run's results are held until the table is written."""
MAX_COORDINATE = 1e7
"""Largest ``|x|`` or ``|y|`` in metres of the region (and of sensor and target positions):
10,000 km, well past any surveillance area; areas and distances stay far from overflow."""
