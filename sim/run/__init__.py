"""Running a scenario: the peers built from it, the discrete-event twin, the world and peer
processes and their launcher, faults, replay, the process pool and one run's summary."""
